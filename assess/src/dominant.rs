//! §8 the dominant indicator: baseline, candidate, hold time T_dom and margin.

use crate::assessment::{Dominant, Indicator};
use crate::config::{BaselineMode, DominantConfig};
use crate::window::seconds_to_ns;

#[derive(Debug, Clone)]
pub(crate) struct DominantTracker {
    cfg: DominantConfig,
    weights: [f64; 5],
    /// The first frame's time [ns].
    t_first_ns: Option<i64>,
    baseline: Option<[f64; 5]>,
    calib_sum: [f64; 5],
    calib_count: u64,
    candidate: Option<Indicator>,
    /// Since when the candidate has been the candidate [ns].
    candidate_since_ns: i64,
    reported: Option<Indicator>,
    /// Since when the reported indicator has been reported [ns].
    reported_since_ns: i64,
    started: bool,
    /// The calibration period [ns].
    calibration_ns: i64,
    /// T_dom [ns].
    hold_ns: i64,
}

impl DominantTracker {
    pub(crate) fn new(cfg: DominantConfig, weights: [f64; 5]) -> Self {
        let baseline = match cfg.baseline_mode {
            BaselineMode::Fixed => Some(cfg.baseline.to_array()),
            BaselineMode::Calibrate => None,
        };
        let calibration_ns = seconds_to_ns(cfg.calibration_s);
        let hold_ns = seconds_to_ns(cfg.hold_s);
        Self {
            cfg,
            weights,
            t_first_ns: None,
            baseline,
            calib_sum: [0.0; 5],
            calib_count: 0,
            candidate: None,
            candidate_since_ns: 0,
            reported: None,
            reported_since_ns: 0,
            started: false,
            calibration_ns,
            hold_ns,
        }
    }

    /// One frame at `t_ns` (the frame time in whole nanoseconds [ns]): `x` is the windowed
    /// x̃, `valid` is v_F. Every time comparison is in whole nanoseconds (MODEL.md).
    pub(crate) fn update(&mut self, t_ns: i64, x: &[f64; 5], valid: bool, out: &mut Dominant) {
        let t0 = *self.t_first_ns.get_or_insert(t_ns);
        if self.baseline.is_none() {
            if t_ns - t0 < self.calibration_ns {
                if valid {
                    for (s, v) in self.calib_sum.iter_mut().zip(x) {
                        *s += v;
                    }
                    self.calib_count += 1;
                }
                *out = Dominant {
                    calibrating: true,
                    ..Dominant::default()
                };
                return;
            }
            self.baseline = Some(if self.calib_count > 0 {
                self.calib_sum.map(|s| s / self.calib_count as f64)
            } else {
                self.cfg.baseline.to_array()
            });
        }
        let b = self.baseline.unwrap_or(self.cfg.baseline.to_array());
        let mut e = [0.0; 5];
        for k in 0..5 {
            e[k] = self.weights[k] * (x[k] - b[k]).max(0.0);
        }
        // argmax with ties to the earlier component; "none" when every e_k ≤ threshold.
        let mut best = 0;
        for k in 1..5 {
            if e[k] > e[best] {
                best = k;
            }
        }
        let candidate = if e[best] <= self.cfg.none_threshold {
            None
        } else {
            Indicator::from_index(best)
        };
        if !self.started {
            self.started = true;
            self.candidate = candidate;
            self.candidate_since_ns = t_ns;
            self.reported = None;
            self.reported_since_ns = t_ns;
        } else if candidate != self.candidate {
            self.candidate = candidate;
            self.candidate_since_ns = t_ns;
        }
        if self.candidate != self.reported && t_ns - self.candidate_since_ns >= self.hold_ns {
            let leads = match (self.candidate, self.reported) {
                (Some(c), Some(r)) => e[c as usize] - e[r as usize] >= self.cfg.margin,
                _ => true,
            };
            if leads {
                self.reported = self.candidate;
                self.reported_since_ns = t_ns;
            }
        }
        *out = Dominant {
            indicator: self.reported,
            strength: self.reported.map_or(0.0, |k| e[k as usize]),
            held_for_s: (t_ns - self.reported_since_ns) as f64 / 1e9,
            candidate: self.candidate,
            contributions: e,
            baseline: Some(b),
            calibrating: false,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ComponentValues;
    use crate::window::tests::float_age;

    /// Frame k of a 25 fps stream: t_k = k · 0.04 s, in whole nanoseconds.
    fn t(k: u32) -> i64 {
        seconds_to_ns(f64::from(k) * 0.04)
    }

    fn fixed() -> DominantTracker {
        let cfg = DominantConfig {
            baseline_mode: BaselineMode::Fixed,
            baseline: ComponentValues::from_array([0.5, 0.15, 0.15, 0.2, 0.1]),
            ..DominantConfig::default()
        };
        DominantTracker::new(cfg, [0.2; 5])
    }

    /// Worked example (by hand), MODEL.md "every time comparison is exact" and "the start,
    /// from none, needs no lead margin": fixed baselines b, weights 0.2. Frames 0–40 sit at
    /// the baseline (every e_k = 0: candidate "none"); from frame 41 (1.64 s) AED is 0.6, so
    /// e_AED = 0.2 · (0.6 − 0.5) = 0.02 > 0.01 and AED is the candidate. It has held exactly
    /// T_dom = 3 s on frame 116 (4.64 s) and is reported there, not on frame 115. In floating
    /// point 116 · 0.04 − 41 · 0.04 = 2.9999999999999996 < 3, and a077dd5 reported it a frame
    /// late.
    #[test]
    fn a_candidate_held_exactly_t_dom_is_reported() {
        assert!(
            float_age(116, 41) < 3.0,
            "the float difference is below T_dom"
        );
        let mut d = fixed();
        let mut out = Dominant::default();
        let at_baseline = [0.5, 0.15, 0.15, 0.2, 0.1];
        let aed_high = [0.6, 0.15, 0.15, 0.2, 0.1];
        for k in 0..=40 {
            d.update(t(k), &at_baseline, true, &mut out);
            assert_eq!(out.candidate, None);
        }
        for k in 41..=115 {
            d.update(t(k), &aed_high, true, &mut out);
            assert_eq!(out.candidate, Some(Indicator::Aed), "frame {k}");
            assert_eq!(out.indicator, None, "frame {k}: held less than 3 s");
        }
        d.update(t(116), &aed_high, true, &mut out);
        assert_eq!(out.indicator, Some(Indicator::Aed), "held exactly 3 s");
        assert!((out.strength - 0.02).abs() < 1e-15, "{}", out.strength);
        assert_eq!(out.held_for_s, 0.0);
        d.update(t(117), &aed_high, true, &mut out);
        assert_eq!(out.held_for_s, 0.04);
    }

    /// Worked example (by hand): the calibration period is 60 s from the first frame. With the
    /// first frame at frame 106 of a 25 fps stream (4.24 s), frame 1605 (64.2 s) still
    /// calibrates and frame 1606 (64.24 s, exactly 60 s later) does not; in floating point
    /// 1606 · 0.04 − 106 · 0.04 = 59.99999999999999 < 60, and a077dd5 calibrated a frame
    /// longer. The baseline is the mean of the valid frames before the end: here 0.4 for
    /// AED (half the frames at 0.3, half at 0.5).
    #[test]
    fn calibration_ends_exactly_sixty_seconds_after_the_first_frame() {
        assert!(float_age(1606, 106) < 60.0);
        let mut d = DominantTracker::new(DominantConfig::default(), [0.2; 5]);
        let mut out = Dominant::default();
        for k in 106..=1605 {
            let aed = if k % 2 == 0 { 0.3 } else { 0.5 };
            d.update(t(k), &[aed, 0.1, 0.1, 0.1, 0.1], true, &mut out);
            assert!(out.calibrating, "frame {k}");
        }
        d.update(t(1606), &[0.4, 0.1, 0.1, 0.1, 0.1], true, &mut out);
        assert!(!out.calibrating, "exactly 60 s after the first frame");
        let b = out.baseline.unwrap();
        assert!((b[0] - 0.4).abs() < 1e-12, "{b:?}");
        assert!((b[1] - 0.1).abs() < 1e-12, "{b:?}");
    }

    /// MODEL.md: "if the calibration period has no valid frame, the config (default)
    /// baselines are used".
    #[test]
    fn a_calibration_without_a_valid_frame_keeps_the_config_baselines() {
        let mut d = DominantTracker::new(DominantConfig::default(), [0.2; 5]);
        let mut out = Dominant::default();
        for k in 0..1500 {
            d.update(t(k), &[0.9; 5], false, &mut out);
        }
        d.update(t(1500), &[0.9; 5], true, &mut out);
        assert_eq!(out.baseline, Some([0.50, 0.15, 0.15, 0.20, 0.10]));
    }
}
