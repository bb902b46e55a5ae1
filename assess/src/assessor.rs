//! The [`Assessor`]: one frame in, one [`Assessment`] out.

use crate::Vec3;
use crate::area::{AreaId, AreaRole, Workspace};
use crate::assessment::{Assessment, Category, Dominant, Indicators};
use crate::config::AssessConfig;
use crate::confirm::Confirmer;
use crate::cue::{CueFrame, Hand};
use crate::dominant::DominantTracker;
use crate::error::Result;
use crate::evidence::{hand_evidence, orientation_evidence};
use crate::filter::OneEuro3;
use crate::hesitation::SpeedSamples;
use crate::window::{FrameContribution, Totals, Window, seconds_to_ns};

const NS_PER_S: f64 = 1e9;

/// A sanitised orientation cue: unit facing, position, confidence.
#[derive(Debug, Clone, Copy)]
struct Orientation {
    position: Vec3,
    facing: Vec3,
    confidence: f64,
}

/// Per-hand filter state (§7): a One-Euro filter per axis and the time of the last sample.
#[derive(Debug, Clone, Copy)]
struct HandTrack {
    filter: OneEuro3,
    last_t: f64,
    /// Filtered speed on the latest frame, when defined [m/s].
    speed: Option<f64>,
}

impl HandTrack {
    /// Feed the hand's position on a frame at `t`, or `None` when the hand is missing.
    fn update(&mut self, t: f64, position: Option<Vec3>) {
        let Some(p) = position else {
            self.filter.reset();
            self.speed = None;
            return;
        };
        if !self.filter.is_initialised() {
            self.filter.filter(p.into(), 0.0);
            self.speed = None;
        } else {
            let dt = t - self.last_t;
            let before = Vec3::from(self.filter.value());
            let after = Vec3::from(self.filter.filter(p.into(), dt));
            let v = (after - before).norm() / dt;
            self.speed = v.is_finite().then_some(v);
        }
        self.last_t = t;
    }
}

/// The attention–action assessment model ([`spec`](crate::spec) §1–8) for one operator.
///
/// [`Assessor::new`] allocates everything; [`Assessor::update`] is O(1) in the trial length and
/// allocates nothing. A frame whose time is not finite or does not increase is rejected: it
/// changes nothing but the rejection counters.
#[derive(Debug, Clone)]
pub struct Assessor {
    ws: Workspace,
    cfg: AssessConfig,
    /// Cost of a switch between every pair of areas, N × N, row-major.
    cost: Vec<f64>,
    confirm: Confirmer,
    confirm_per: Confirmer,
    confirm_act: Confirmer,
    /// Cue evidence per area on the last frame: (head, body, hand).
    evidence: Vec<[f64; 3]>,
    /// Fused score S_i per area on the last frame.
    scores: Vec<f64>,
    /// Distance of the active hand to every area's box on the last frame [m].
    hand_distance: Vec<f64>,
    hands: [HandTrack; 2],
    /// The last `turn_lookback_frames` valid body frames, (t, yaw), as a ring.
    yaw_ring: Vec<(f64, f64)>,
    yaw_next: usize,
    yaw_len: usize,
    /// Time and rounded absolute time [ns] of the last accepted frame.
    last_t: Option<(f64, i64)>,
    /// Δt_max [ns].
    dt_max_ns: i64,
    /// The median's minimum sample time [ns] (§7).
    min_sample_ns: i64,
    /// t_min [ns] (§7).
    t_min_ns: i64,
    seq: u64,
    last_area: Option<AreaId>,
    totals: Totals,
    window: Window,
    samples: SpeedSamples,
    run_ns: i64,
    run_start_seq: u64,
    run_counting: bool,
    dominant: DominantTracker,
    out: Assessment,
}

impl Assessor {
    /// Builds an assessor for a calibrated workspace. Fails when `cfg` breaks a rule (see
    /// [`AssessConfig::validate`]).
    pub fn new(workspace: Workspace, cfg: AssessConfig) -> Result<Self> {
        cfg.validate()?;
        let n = workspace.len();
        let mut cost = vec![0.0; n * n];
        for a in 0..n {
            for b in 0..n {
                if a != b {
                    cost[a * n + b] =
                        pair_cost(&cfg, workspace.role(AreaId(a)), workspace.role(AreaId(b)));
                }
            }
        }
        let m = cfg.confirmation.window_frames;
        let track = HandTrack {
            filter: OneEuro3::new(cfg.hesitation.one_euro),
            last_t: 0.0,
            speed: None,
        };
        let out = Assessment {
            t: 0.0,
            frames: 0,
            rejected_frames: 0,
            last_rejected: false,
            dt_s: 0.0,
            valid: false,
            present: [false; 3],
            turning: false,
            weights: [0.0; 3],
            raw: None,
            raw_score: 0.0,
            confirmed: None,
            perceptual: (None, false),
            action: (None, false),
            active_hand: None,
            hand_speed_m_s: None,
            speed_threshold_m_s: cfg.hesitation.v_max_m_s,
            low_motion: false,
            hesitating: false,
            collaborating: false,
            switch_cost: None,
            switches: 0,
            cumulative: Indicators::default(),
            windowed: Indicators::default(),
            area_demand: vec![0.0; n],
            area_demand_windowed: vec![0.0; n],
            dominant: Dominant::default(),
            window_overflow: false,
        };
        Ok(Self {
            confirm: Confirmer::new(n, m),
            confirm_per: Confirmer::new(n, m),
            confirm_act: Confirmer::new(n, m),
            evidence: vec![[0.0; 3]; n],
            scores: vec![0.0; n],
            hand_distance: vec![f64::INFINITY; n],
            hands: [track; 2],
            yaw_ring: vec![(0.0, 0.0); cfg.fusion.turn_lookback_frames],
            yaw_next: 0,
            yaw_len: 0,
            last_t: None,
            dt_max_ns: seconds_to_ns(cfg.demand.max_frame_interval_s),
            min_sample_ns: seconds_to_ns(cfg.hesitation.min_sample_time_s),
            t_min_ns: seconds_to_ns(cfg.hesitation.min_duration_s),
            seq: 0,
            last_area: None,
            totals: Totals::new(n),
            window: Window::new(n, cfg.window.horizon_s, cfg.window.max_rate_hz),
            samples: SpeedSamples::new(cfg.hesitation.median_horizon_s, cfg.window.max_rate_hz),
            run_ns: 0,
            run_start_seq: 0,
            run_counting: false,
            dominant: DominantTracker::new(cfg.dominant.clone(), cfg.composite.weights.to_array()),
            cost,
            ws: workspace,
            cfg,
            out,
        })
    }

    /// The calibrated workspace.
    pub fn workspace(&self) -> &Workspace {
        &self.ws
    }

    /// The configuration in force.
    pub fn config(&self) -> &AssessConfig {
        &self.cfg
    }

    /// §1 cue evidence (S_i^h, S_i^b, S_i^m) of every area on the last accepted frame [-];
    /// 0 for a missing cue.
    pub fn cue_evidence(&self) -> &[[f64; 3]] {
        &self.evidence
    }

    /// §2 fused score S_i of every area on the last accepted frame [-].
    pub fn fused_scores(&self) -> &[f64] {
        &self.scores
    }

    /// The latest assessment (the one the last `update` returned).
    pub fn assessment(&self) -> &Assessment {
        &self.out
    }

    /// Assess one frame. O(1) per frame, no allocation.
    pub fn update(&mut self, frame: &CueFrame) -> &Assessment {
        let t = frame.t;
        if !t.is_finite() || self.last_t.is_some_and(|(prev, _)| t <= prev) {
            self.out.rejected_frames += 1;
            self.out.last_rejected = true;
            return &self.out;
        }
        // Integrals use differences of absolute times rounded to whole nanoseconds, so the
        // sum of the Δt over any run of frames equals the run's duration to ±1 ns, with no
        // rounding error accumulating (e.g. nine frames at 30 fps are exactly 0.3 s).
        let t_ns = seconds_to_ns(t);
        let dt_ns = match self.last_t {
            None => 0,
            Some((_, prev_ns)) => (t_ns - prev_ns).clamp(0, self.dt_max_ns),
        };
        self.last_t = Some((t, t_ns));
        let seq = self.seq;
        self.seq += 1;

        // --- cues (a non-finite or low-confidence cue is missing) ---
        let c_min = self.cfg.fusion.min_confidence;
        let head = frame
            .head
            .and_then(|h| orientation(h.position, h.facing, h.confidence, c_min));
        let body = frame
            .body
            .and_then(|b| orientation(b.position, b.facing, b.confidence, c_min));
        let mut hand_cues = [None; 2];
        for (slot, cue) in hand_cues.iter_mut().zip(frame.hands.iter()) {
            *slot = cue.and_then(|h| {
                let ok = h.position.iter().all(|v| v.is_finite())
                    && h.confidence.is_finite()
                    && h.confidence >= c_min;
                ok.then_some((h.position, h.confidence.min(1.0)))
            });
        }
        for (track, cue) in self.hands.iter_mut().zip(hand_cues.iter()) {
            track.update(t, cue.map(|c| c.0));
        }
        let active = self.active_hand(&hand_cues);
        let hand = active.and_then(|h| hand_cues[h as usize]);
        let present = [head.is_some(), body.is_some(), hand.is_some()];
        let valid = present.iter().any(|&p| p);

        // --- §2 weights: turn detection, confidence, renormalisation ---
        let turning = body.is_some_and(|b| self.detect_turn(t, &b.facing));
        let base = if turning {
            self.cfg.fusion.turn_weights
        } else {
            self.cfg.fusion.weights
        };
        let raw_w = [
            head.map_or(0.0, |h| base.head * h.confidence),
            body.map_or(0.0, |b| base.body * b.confidence),
            hand.map_or(0.0, |m| base.hand * m.1),
        ];
        let weights = normalise(raw_w);
        let per_weights = normalise([raw_w[0], raw_w[1], 0.0]);

        // --- §1 evidence per area, §2 fusion and raw state ---
        let d_ws = self.ws.diagonal();
        let tau = self.cfg.fusion.tau;
        let mut best = (0usize, f64::NEG_INFINITY);
        let mut best_per = (0usize, f64::NEG_INFINITY);
        for (i, area) in self.ws.areas().iter().enumerate() {
            let r = &area.representative_centre;
            let d_hand = hand.map_or(f64::INFINITY, |m| area.shape.distance(&m.0));
            self.hand_distance[i] = d_hand;
            let e = [
                head.map_or(0.0, |h| orientation_evidence(&h.facing, &h.position, r)),
                body.map_or(0.0, |b| orientation_evidence(&b.facing, &b.position, r)),
                hand.map_or(0.0, |_| hand_evidence(d_hand, d_ws)),
            ];
            self.evidence[i] = e;
            let s = weights[0] * e[0] + weights[1] * e[1] + weights[2] * e[2];
            self.scores[i] = s;
            if s > best.1 {
                best = (i, s);
            }
            let s_per = per_weights[0] * e[0] + per_weights[1] * e[1];
            if s_per > best_per.1 {
                best_per = (i, s_per);
            }
        }
        let raw = (best.1 >= tau).then_some(AreaId(best.0));

        // --- §3 confirmation (invalid frames are not pushed: F(t) = F(t−1)) ---
        let prev_f = self.confirm.state();
        let f = if valid {
            self.confirm.push(raw)
        } else {
            prev_f
        };

        // --- §5 perceptual and action sub-states ---
        let per_valid = present[0] || present[1];
        let act_valid = present[2];
        if per_valid {
            self.confirm_per
                .push((best_per.1 >= tau).then_some(AreaId(best_per.0)));
        }
        if hand.is_some() {
            let raw_act = self.action_area();
            self.confirm_act.push(raw_act);
        }
        let f_per = self.confirm_per.state();
        let f_act = self.confirm_act.state();
        let ab_valid = per_valid && act_valid;

        // --- §6 switch events: between two areas; A → ∅ → B counts once as A → B ---
        let mut switch_cost = None;
        if let Some(b) = f {
            if let Some(a) = self.last_area {
                // a ≠ b implies a change: last_area equals F(t−1) whenever F(t−1) is an area.
                if a != b {
                    switch_cost = Some(self.cost[a.0 * self.ws.len() + b.0]);
                }
            }
            self.last_area = Some(b);
        }

        // --- §7 hesitation ---
        let h_cfg = &self.cfg.hesitation;
        let speed = active.and_then(|h| self.hands[h as usize].speed);
        self.samples.expire(t_ns);
        let v_th = if self.samples.sum_dt_ns() < self.min_sample_ns {
            h_cfg.v_max_m_s
        } else {
            let med = self.samples.median().unwrap_or(f64::INFINITY);
            (h_cfg.k_v * med).clamp(h_cfg.v_min_m_s, h_cfg.v_max_m_s)
        };
        let c = frame.robot.collaborating;
        let low_motion = c && frame.robot.incomplete && speed.is_some_and(|v| v < v_th);
        let mut hesitating = false;
        let mut retro_from = None;
        if low_motion {
            if self.run_ns == 0 && !self.run_counting {
                self.run_start_seq = seq;
            }
            self.run_ns += dt_ns;
            if self.run_counting {
                hesitating = true;
                self.totals.hes_ns += dt_ns;
            } else if self.run_ns >= self.t_min_ns {
                // The run reached t_min: its whole length counts, retroactively.
                self.run_counting = true;
                hesitating = true;
                self.totals.hes_ns += self.run_ns;
                retro_from = Some(self.run_start_seq);
            }
        } else {
            self.run_ns = 0;
            self.run_counting = false;
        }
        if c && let Some(v) = speed {
            self.samples.push(t_ns, v, dt_ns);
        }

        // --- §4 integrals, cumulative and windowed ---
        let contribution = FrameContribution {
            t_ns,
            dt_ns,
            valid,
            state: f.map_or(self.ws.len(), |a| a.0) as u16,
            ab_valid,
            ab_inconsistent: ab_valid && f_per != f_act,
            collaborating: c,
            hesitating,
            switch_cost: switch_cost.unwrap_or(0.0),
        };
        // T_hes is maintained directly above (it can grow retroactively).
        let hes_before = self.totals.hes_ns;
        self.totals.apply(&contribution, 1);
        self.totals.hes_ns = hes_before;
        self.window.push(seq, contribution);
        if let Some(from) = retro_from {
            self.window.mark_hesitation(from, seq.saturating_sub(1));
        }

        // --- §8 indicators, composite, dominant ---
        let out = &mut self.out;
        out.t = t;
        out.frames += 1;
        out.last_rejected = false;
        out.dt_s = dt_ns as f64 / NS_PER_S;
        out.valid = valid;
        out.present = present;
        out.turning = turning;
        out.weights = weights;
        out.raw = raw;
        out.raw_score = best.1.max(0.0);
        out.confirmed = f;
        out.perceptual = (f_per, per_valid);
        out.action = (f_act, act_valid);
        out.active_hand = active;
        out.hand_speed_m_s = speed;
        out.speed_threshold_m_s = v_th;
        out.low_motion = low_motion;
        out.hesitating = hesitating;
        out.collaborating = c;
        out.switch_cost = switch_cost;
        if switch_cost.is_some() {
            out.switches += 1;
        }
        out.window_overflow = self.window.overflowed;
        indicators(
            &self.ws,
            &self.cfg,
            &self.totals,
            &mut out.cumulative,
            &mut out.area_demand,
        );
        indicators(
            &self.ws,
            &self.cfg,
            &self.window.totals,
            &mut out.windowed,
            &mut out.area_demand_windowed,
        );
        self.dominant
            .update(t_ns, &out.windowed.components(), valid, &mut out.dominant);
        &self.out
    }

    /// §Inputs: with two hands, the one closer to any area centre; ties to the faster hand.
    fn active_hand(&self, cues: &[Option<(Vec3, f64)>; 2]) -> Option<Hand> {
        match (cues[0], cues[1]) {
            (None, None) => None,
            (Some(_), None) => Some(Hand::Left),
            (None, Some(_)) => Some(Hand::Right),
            (Some((l, _)), Some((r, _))) => {
                let near = |p: &Vec3| {
                    self.ws
                        .areas()
                        .iter()
                        .map(|a| (p - a.representative_centre).norm_squared())
                        .fold(f64::INFINITY, f64::min)
                };
                let (dl, dr) = (near(&l), near(&r));
                if dl < dr {
                    Some(Hand::Left)
                } else if dr < dl {
                    Some(Hand::Right)
                } else {
                    let vl = self.hands[0].speed.unwrap_or(0.0);
                    let vr = self.hands[1].speed.unwrap_or(0.0);
                    Some(if vr > vl { Hand::Right } else { Hand::Left })
                }
            }
        }
    }

    /// §5: the area containing the active hand, else the nearest within d_act, else ∅ (ties:
    /// first). Uses the distances computed for the evidence on this frame.
    fn action_area(&self) -> Option<AreaId> {
        let mut nearest: Option<(usize, f64)> = None;
        for (i, &d) in self.hand_distance.iter().enumerate() {
            if d == 0.0 {
                return Some(AreaId(i));
            }
            if d <= self.cfg.demand.action_radius_m && nearest.is_none_or(|(_, dn)| d < dn) {
                nearest = Some((i, d));
            }
        }
        nearest.map(|(i, _)| AreaId(i))
    }

    /// §2: a large reorientation when |Δyaw| to the frame `turn_lookback_frames` valid body
    /// frames earlier, over their time difference, exceeds the threshold. Records this frame.
    fn detect_turn(&mut self, t: f64, facing: &Vec3) -> bool {
        let horizontal = facing.x.hypot(facing.y);
        if horizontal < 1e-9 {
            return false;
        }
        let yaw = facing.y.atan2(facing.x);
        let k = self.yaw_ring.len();
        let mut turning = false;
        if self.yaw_len == k {
            // The slot about to be overwritten holds the frame k valid body frames earlier.
            let (t_then, yaw_then) = self.yaw_ring[self.yaw_next];
            // Both yaws are in [−π, π], so one wrap brings the difference into [−π, π].
            let mut d = yaw - yaw_then;
            if d > std::f64::consts::PI {
                d -= std::f64::consts::TAU;
            } else if d < -std::f64::consts::PI {
                d += std::f64::consts::TAU;
            }
            let rate = d.abs() / (t - t_then);
            turning = rate > self.cfg.fusion.turn_yaw_rate_deg_s.to_radians();
        } else {
            self.yaw_len += 1;
        }
        self.yaw_ring[self.yaw_next] = (t, yaw);
        self.yaw_next = (self.yaw_next + 1) % k;
        turning
    }
}

fn orientation(position: Vec3, facing: Vec3, confidence: f64, c_min: f64) -> Option<Orientation> {
    let finite =
        position.iter().chain(facing.iter()).all(|v| v.is_finite()) && confidence.is_finite();
    // Any non-zero length is a direction (MODEL.md): scaled by its largest component first,
    // so that a tiny vector's squares do not underflow to a zero norm.
    let largest = facing.amax();
    if !(finite && largest > 0.0 && confidence >= c_min) {
        return None;
    }
    let scaled = facing / largest;
    Some(Orientation {
        position,
        facing: scaled / scaled.norm(),
        confidence: confidence.min(1.0),
    })
}

fn normalise(w: [f64; 3]) -> [f64; 3] {
    let s = w[0] + w[1] + w[2];
    if s > 0.0 { w.map(|x| x / s) } else { [0.0; 3] }
}

/// §6 c(a, b) for a ≠ b.
fn pair_cost(cfg: &AssessConfig, a: Option<AreaRole>, b: Option<AreaRole>) -> f64 {
    use AreaRole::*;
    let s = &cfg.switching;
    match (a, b) {
        (Some(Instruction), Some(Assembly)) | (Some(Assembly), Some(Instruction)) => s.cost_high,
        (Some(Collaboration), Some(ToolIdentification))
        | (Some(ToolIdentification), Some(Collaboration)) => s.cost_int,
        _ => s.cost_base,
    }
}

fn ratio(num: i64, den: i64) -> f64 {
    if den > 0 {
        (num as f64 / den as f64).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// §4–8 from integrals.
fn indicators(
    ws: &Workspace,
    cfg: &AssessConfig,
    tot: &Totals,
    out: &mut Indicators,
    area_demand: &mut [f64],
) {
    for (d, &ns) in area_demand.iter_mut().zip(tot.area_ns.iter()) {
        *d = ratio(ns, tot.valid_ns);
    }
    let by_role = |role| ws.by_role(role).map_or(0.0, |id: AreaId| area_demand[id.0]);
    out.aed = by_role(AreaRole::Assembly);
    out.tid = by_role(AreaRole::ToolIdentification);
    out.icd = by_role(AreaRole::Instruction);
    out.col = by_role(AreaRole::Collaboration);
    out.abi = ratio(tot.ab_inconsistent_ns, tot.ab_valid_ns);
    let t_v = tot.valid_ns as f64 / NS_PER_S;
    out.asd_ctx = if tot.valid_ns > 0 {
        (tot.switch_cost / t_v).max(0.0)
    } else {
        0.0
    };
    out.asd_norm = (out.asd_ctx / cfg.composite.asd_ref_per_s).min(1.0);
    let t_collab = tot.collab_ns as f64 / NS_PER_S;
    let t_hes = tot.hes_ns as f64 / NS_PER_S;
    out.ohd = (t_hes / (t_collab + cfg.hesitation.epsilon_s)).clamp(0.0, 1.0);
    let w = cfg.composite.weights.to_array();
    out.hrc_cwl = w
        .iter()
        .zip(out.components())
        .map(|(w, x)| w * x)
        .sum::<f64>()
        .clamp(0.0, 1.0);
    out.category = if out.hrc_cwl < cfg.composite.medium_from {
        Category::Low
    } else if out.hrc_cwl < cfg.composite.high_from {
        Category::Medium
    } else {
        Category::High
    };
    out.valid_time_s = t_v;
    out.switch_cost = tot.switch_cost;
    out.hesitation_time_s = t_hes;
    out.collaboration_time_s = t_collab;
    out.ab_valid_time_s = tot.ab_valid_ns as f64 / NS_PER_S;
    out.ab_inconsistent_time_s = tot.ab_inconsistent_ns as f64 / NS_PER_S;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// MODEL.md / README: a facing vector of any non-zero length is a direction. a077dd5
    /// dropped one of length ≤ 1e-9 as missing; a length of 1e-200 squares to 0 in floating
    /// point, so the direction is scaled before it is normalised.
    #[test]
    fn a_facing_vector_of_any_non_zero_length_is_used() {
        let p = Vec3::new(0.0, 0.0, 1.0);
        for len in [1.0, 1e-9, 1e-12, 1e-200, 5e-324] {
            let o = orientation(p, Vec3::new(0.0, len, 0.0), 0.9, 0.5)
                .unwrap_or_else(|| panic!("length {len:e} dropped"));
            assert_eq!(o.facing, Vec3::new(0.0, 1.0, 0.0), "length {len:e}");
        }
        let o = orientation(p, Vec3::new(3e-200, 4e-200, 0.0), 0.9, 0.5).unwrap();
        assert!((o.facing - Vec3::new(0.6, 0.8, 0.0)).norm() < 1e-15);
        assert!(
            orientation(p, Vec3::zeros(), 0.9, 0.5).is_none(),
            "zero: no direction"
        );
        assert!(orientation(p, Vec3::new(f64::NAN, 1.0, 0.0), 0.9, 0.5).is_none());
        assert!(
            orientation(p, Vec3::new(0.0, 1.0, 0.0), 0.4, 0.5).is_none(),
            "c < c_min"
        );
    }
}
