//! §8 the dominant indicator: baseline, candidate, hold time T_dom and margin.

use crate::assessment::{Dominant, Indicator};
use crate::config::{BaselineMode, DominantConfig};

#[derive(Debug, Clone)]
pub(crate) struct DominantTracker {
    cfg: DominantConfig,
    weights: [f64; 5],
    t_first: Option<f64>,
    baseline: Option<[f64; 5]>,
    calib_sum: [f64; 5],
    calib_count: u64,
    candidate: Option<Indicator>,
    candidate_since: f64,
    reported: Option<Indicator>,
    reported_since: f64,
    started: bool,
}

impl DominantTracker {
    pub(crate) fn new(cfg: DominantConfig, weights: [f64; 5]) -> Self {
        let baseline = match cfg.baseline_mode {
            BaselineMode::Fixed => Some(cfg.baseline.to_array()),
            BaselineMode::Calibrate => None,
        };
        Self {
            cfg,
            weights,
            t_first: None,
            baseline,
            calib_sum: [0.0; 5],
            calib_count: 0,
            candidate: None,
            candidate_since: 0.0,
            reported: None,
            reported_since: 0.0,
            started: false,
        }
    }

    /// One frame: `x` is the windowed x̃, `valid` is v_F.
    pub(crate) fn update(&mut self, t: f64, x: &[f64; 5], valid: bool, out: &mut Dominant) {
        let t0 = *self.t_first.get_or_insert(t);
        if self.baseline.is_none() {
            if t - t0 < self.cfg.calibration_s {
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
            self.candidate_since = t;
            self.reported = None;
            self.reported_since = t;
        } else if candidate != self.candidate {
            self.candidate = candidate;
            self.candidate_since = t;
        }
        if self.candidate != self.reported && t - self.candidate_since >= self.cfg.hold_s {
            let leads = match (self.candidate, self.reported) {
                (Some(c), Some(r)) => e[c as usize] - e[r as usize] >= self.cfg.margin,
                _ => true,
            };
            if leads {
                self.reported = self.candidate;
                self.reported_since = t;
            }
        }
        *out = Dominant {
            indicator: self.reported,
            strength: self.reported.map_or(0.0, |k| e[k as usize]),
            held_for_s: t - self.reported_since,
            candidate: self.candidate,
            contributions: e,
            baseline: Some(b),
            calibrating: false,
        };
    }
}
