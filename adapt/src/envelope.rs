//! The speed the planner allows itself near the operator: the safety supervisor's own limits
//! (joint speed, TCP speed and its collaboration cap, perception staleness, and ISO/TS 15066
//! separation from every tracked body part to every arm capsule), with margins, turned into
//! the largest admissible time-scaling factor `s` at a point of the planned path.
//!
//! The planner and the supervisor share the *formulas* (the protective separation distance of
//! `robot_io::separation` and the capsule geometry of `robot_io::geometry`) and the *numbers*
//! ([`SafetyEnvelope`] is built from the supervisor's configuration by the binary; a cross-crate
//! test checks they agree), never a code path: the supervisor checks each command on its own.
//!
//! # Admissible scale at one path sample
//! At a path sample with joints `q` [rad] and path velocity `q'` [rad/s], running the path at
//! scale `s` gives joint speeds `s·q'` and a flange speed `s·u`, `u = |J(q) q'|` [m/s]. With the
//! planning fraction `f < 1` of every cap:
//!
//! ```text
//! joint:       s ≤ f · v_joint · k_stale / max|q'|
//! TCP:         s ≤ f · v_tcp(C) · k_stale / u          (v_tcp = 0.25 m/s while C(t), else 1 m/s)
//! separation:  S_p(s) + δ ≤ d   for every body part, with
//!              S_p(s) = v_h (T_age + T_r + T_s(s)) + v_r(s) T_r + v_r(s) T_s(s)/2 + C + Z_d + Z_r,
//!              v_r(s) = (1+ε) s u,  T_s(s) = (1+ε) s max|q'| / a_stop
//! ```
//! `S_p(s)` is the supervisor's formula with the robot's speed expressed through `s`; it is a
//! quadratic `c0 + c1 s + c2 s²` (c1, c2 ≥ 0), whose coefficients are taken from three
//! evaluations of the shared `protective_distance_m` (exact for a quadratic). The largest `s`
//! with `c0 + c1 s + c2 s² ≤ d − δ` is `s* = −2γ / (c1 + √(c1² − 4 c2 γ))`, `γ = c0 − (d − δ)`,
//! and 0 when `γ ≥ 0` (the part is inside the protective distance even at rest). `d` is the
//! capsule-to-capsule surface distance, taken as the smaller of the distance at `q` and at the
//! stopping configuration the supervisor also checks. `ε` allows for the measured speed
//! lagging the command (the supervisor takes the larger of the two), `δ` is a distance margin.
//!
//! # Example
//! ```
//! use adapt::envelope::{Envelope, PlanningMargins, SafetyEnvelope};
//! use robot_io::geometry::HumanBody;
//! let mut env = Envelope::new(SafetyEnvelope::ur5e(), PlanningMargins::default());
//! let q = [0.0, -1.2, 1.3, -1.7, -1.57, 0.0];
//! let qd = [0.2, 0.0, 0.0, 0.0, 0.0, 0.0];
//! // Nobody near: only the speed caps bind (0.9 × 0.25 m/s while collaborating).
//! let a = env.admissible_scale(&q, &qd, &HumanBody::default(), 0.0, true);
//! assert!(a.scale > 0.0);
//! ```

use robot_io::Joints;
use robot_io::geometry::{
    ARM_CAPSULES, Approach, ArmModel, BodyModel, BodyPart, Capsule, HumanBody, closest_approaches,
};
use robot_io::kinematics::flange_pose;
use robot_io::separation::{SeparationParams, protective_distance_m};
use serde::Deserialize;

use crate::error::positive;
use crate::{AdaptError, Result};

/// The supervisor's limits as the planner must respect them (all validated: finite, > 0 where
/// a division uses them). The binary builds it from `safety::SupervisorConfig`;
/// [`SafetyEnvelope::ur5e`] equals `SupervisorConfig::ur5e()`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetyEnvelope {
    joint_speed_rad_s: f64,
    joint_acceleration_rad_s2: f64,
    stop_deceleration_rad_s2: f64,
    tcp_speed_m_s: f64,
    collaboration_tcp_speed_m_s: f64,
    stale_perception_scale: f64,
    perception_reduce_after_s: f64,
    separation: SeparationParams,
    arm: ArmModel,
    body: BodyModel,
    catch_up_cycles: u32,
}

/// The UR5e's catch-up bound [cycles]: our program extrapolates a servo target for 3 cycles
/// (6 ms), + 1 (`safety::CatchUpCycles::ur5e`).
const UR5E_CATCH_UP_CYCLES: u32 = 4;
/// The largest catch-up bound accepted [cycles] (`safety::CatchUpCycles::MAX`).
const MAX_CATCH_UP_CYCLES: u32 = 64;

impl SafetyEnvelope {
    /// The envelope from the supervisor's limits: joint speed [rad/s], joint acceleration
    /// [rad/s²], the supervisor's stop deceleration [rad/s²], TCP speed cap [m/s], TCP cap
    /// while collaborating [m/s], speed scale while perception is stale [-] in (0, 1], the
    /// perception age after which it applies [s], and the shared separation and geometry
    /// models.
    ///
    /// # Errors
    /// [`AdaptError::InvalidValue`] naming the value that is not finite and > 0 (or a scale
    /// above 1, or a collaboration cap above the TCP cap).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        joint_speed_rad_s: f64,
        joint_acceleration_rad_s2: f64,
        stop_deceleration_rad_s2: f64,
        tcp_speed_m_s: f64,
        collaboration_tcp_speed_m_s: f64,
        stale_perception_scale: f64,
        perception_reduce_after_s: f64,
        separation: SeparationParams,
        arm: ArmModel,
        body: BodyModel,
    ) -> Result<SafetyEnvelope> {
        let e = SafetyEnvelope {
            joint_speed_rad_s: positive("envelope.joint_speed_rad_s", joint_speed_rad_s)?,
            joint_acceleration_rad_s2: positive(
                "envelope.joint_acceleration_rad_s2",
                joint_acceleration_rad_s2,
            )?,
            stop_deceleration_rad_s2: positive(
                "envelope.stop_deceleration_rad_s2",
                stop_deceleration_rad_s2,
            )?,
            tcp_speed_m_s: positive("envelope.tcp_speed_m_s", tcp_speed_m_s)?,
            collaboration_tcp_speed_m_s: positive(
                "envelope.collaboration_tcp_speed_m_s",
                collaboration_tcp_speed_m_s,
            )?,
            stale_perception_scale: positive(
                "envelope.stale_perception_scale",
                stale_perception_scale,
            )?,
            perception_reduce_after_s: positive(
                "envelope.perception_reduce_after_s",
                perception_reduce_after_s,
            )?,
            separation,
            arm,
            body,
            catch_up_cycles: UR5E_CATCH_UP_CYCLES,
        };
        if e.stale_perception_scale > 1.0 {
            return Err(AdaptError::InvalidValue {
                key: "envelope.stale_perception_scale".to_owned(),
                rule: format!("must be <= 1, got {}", e.stale_perception_scale),
            });
        }
        if e.collaboration_tcp_speed_m_s > e.tcp_speed_m_s {
            return Err(AdaptError::InvalidValue {
                key: "envelope.collaboration_tcp_speed_m_s".to_owned(),
                rule: "must be <= tcp_speed_m_s".to_owned(),
            });
        }
        Ok(e)
    }

    /// The UR5e supervisor defaults (`safety::SupervisorConfig::ur5e()`): π rad/s, π rad/s²,
    /// stops at π rad/s², TCP 1 m/s and 0.25 m/s while collaborating, ×0.25 after 0.2 s of
    /// stale perception, the shared default separation, arm and body models.
    pub fn ur5e() -> SafetyEnvelope {
        let pi = std::f64::consts::PI;
        SafetyEnvelope {
            joint_speed_rad_s: pi,
            joint_acceleration_rad_s2: pi,
            stop_deceleration_rad_s2: pi,
            tcp_speed_m_s: 1.0,
            collaboration_tcp_speed_m_s: 0.25,
            stale_perception_scale: 0.25,
            perception_reduce_after_s: 0.2,
            separation: SeparationParams::handover_default(),
            arm: ArmModel::ur5e_gripper(),
            body: BodyModel::default_adult(),
            catch_up_cycles: UR5E_CATCH_UP_CYCLES,
        }
    }

    /// The same envelope with the supervisor's `command_period_cycles` [cycles], in 1..=64
    /// (4, the UR5e's, unless set): after missed cycles the controller advances its plan by at
    /// most this many cycles, the longest the supervisor judges one servo step over.
    ///
    /// # Errors
    /// [`AdaptError::InvalidValue`] outside 1..=64.
    pub fn with_catch_up_cycles(mut self, cycles: u32) -> Result<SafetyEnvelope> {
        if !(1..=MAX_CATCH_UP_CYCLES).contains(&cycles) {
            return Err(AdaptError::InvalidValue {
                key: "envelope.catch_up_cycles".to_owned(),
                rule: format!("must be in 1..={MAX_CATCH_UP_CYCLES}, got {cycles}"),
            });
        }
        self.catch_up_cycles = cycles;
        Ok(self)
    }

    /// Joint speed cap [rad/s].
    pub fn joint_speed_rad_s(&self) -> f64 {
        self.joint_speed_rad_s
    }
    /// Joint acceleration cap [rad/s²].
    pub fn joint_acceleration_rad_s2(&self) -> f64 {
        self.joint_acceleration_rad_s2
    }
    /// The supervisor's stop deceleration [rad/s²].
    pub fn stop_deceleration_rad_s2(&self) -> f64 {
        self.stop_deceleration_rad_s2
    }
    /// TCP speed cap [m/s].
    pub fn tcp_speed_m_s(&self) -> f64 {
        self.tcp_speed_m_s
    }
    /// TCP speed cap while collaborating [m/s].
    pub fn collaboration_tcp_speed_m_s(&self) -> f64 {
        self.collaboration_tcp_speed_m_s
    }
    /// Speed scale while perception is stale [-].
    pub fn stale_perception_scale(&self) -> f64 {
        self.stale_perception_scale
    }
    /// Perception age after which the stale scale applies [s].
    pub fn perception_reduce_after_s(&self) -> f64 {
        self.perception_reduce_after_s
    }
    /// The separation parameters.
    pub fn separation(&self) -> &SeparationParams {
        &self.separation
    }
    /// The arm's capsule model.
    pub fn arm(&self) -> &ArmModel {
        &self.arm
    }
    /// The operator's body model.
    pub fn body(&self) -> &BodyModel {
        &self.body
    }
    /// The most cycles one controller step catches up after missed cycles [cycles].
    pub fn catch_up_cycles(&self) -> u32 {
        self.catch_up_cycles
    }
}

/// How far inside the supervisor's limits the planner stays, as the config file gives it
/// (`[controller.planning]`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPlanningMargins {
    /// Fraction of every speed cap the plan may use [-], in (0, 1).
    pub speed_fraction: f64,
    /// Distance kept beyond the protective separation distance [m], ≥ 0.
    pub distance_margin_m: f64,
    /// Relative allowance for the measured speed exceeding the commanded one [-], ≥ 0.
    pub measured_speed_allowance: f64,
    /// The planner takes the perception age as at least this (a frame period and latency)
    /// [s], ≥ 0.
    pub perception_age_margin_s: f64,
    /// Upper bound of the time-scale rate ṡ_max [1/s], > 0.
    pub max_scale_rate_per_s: f64,
    /// Upper bound of the time-scale acceleration s̈_max [1/s²], > 0.
    pub max_scale_accel_per_s2: f64,
}

/// Validated [`RawPlanningMargins`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanningMargins {
    raw: RawPlanningMargins,
}

impl Default for PlanningMargins {
    /// 0.9 of every cap, 0.05 m beyond S_p, 10 % measured-speed allowance, a perception age
    /// of at least 0.05 s, ṡ_max ≤ 4 /s, s̈_max ≤ 40 /s².
    fn default() -> Self {
        PlanningMargins {
            raw: RawPlanningMargins {
                speed_fraction: 0.9,
                distance_margin_m: 0.05,
                measured_speed_allowance: 0.1,
                perception_age_margin_s: 0.05,
                max_scale_rate_per_s: 4.0,
                max_scale_accel_per_s2: 40.0,
            },
        }
    }
}

impl TryFrom<RawPlanningMargins> for PlanningMargins {
    type Error = AdaptError;

    fn try_from(raw: RawPlanningMargins) -> Result<PlanningMargins> {
        let f = raw.speed_fraction;
        if !(f.is_finite() && f > 0.0 && f < 1.0) {
            return Err(AdaptError::InvalidValue {
                key: "planning.speed_fraction".to_owned(),
                rule: format!("must be in (0, 1), got {f}"),
            });
        }
        for (key, v) in [
            ("planning.distance_margin_m", raw.distance_margin_m),
            (
                "planning.measured_speed_allowance",
                raw.measured_speed_allowance,
            ),
            (
                "planning.perception_age_margin_s",
                raw.perception_age_margin_s,
            ),
        ] {
            if !(v.is_finite() && (0.0..=10.0).contains(&v)) {
                return Err(AdaptError::InvalidValue {
                    key: key.to_owned(),
                    rule: format!("must be finite and in [0, 10], got {v}"),
                });
            }
        }
        positive("planning.max_scale_rate_per_s", raw.max_scale_rate_per_s)?;
        positive(
            "planning.max_scale_accel_per_s2",
            raw.max_scale_accel_per_s2,
        )?;
        Ok(PlanningMargins { raw })
    }
}

impl PlanningMargins {
    /// The validated values.
    pub fn get(&self) -> &RawPlanningMargins {
        &self.raw
    }
}

/// Which limit set the admissible scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Binding {
    /// Nothing binds (scale 1).
    None,
    /// A joint speed cap.
    JointSpeed,
    /// The TCP speed cap (or its collaboration value).
    TcpSpeed,
    /// Separation from this body part.
    Separation(BodyPart),
    /// Unusable input (non-finite joints or distances): the scale is 0.
    Invalid,
}

/// The largest admissible scale at one path sample, and what set it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Admissible {
    /// Largest admissible `s` [-] in [0, 1].
    pub scale: f64,
    /// The limit that set it.
    pub binding: Binding,
    /// Smallest body-to-arm surface distance at this sample [m] (∞ when nobody is tracked).
    pub min_distance_m: f64,
}

/// Evaluates [`Admissible`] scales; holds the preallocated capsule buffers. Allocates nothing.
///
/// It remembers its last results (exact caches, keyed on the bits of every input a result
/// depends on): the two latest admissible scales, the two latest joint positions' arm capsules
/// and the latest flange speed. The lookahead asks for the same sample many times when the
/// path has finished (every sample is its end) or twice per sample (the operator now and as
/// predicted), and between perception frames the operator does not move.
#[derive(Debug, Clone)]
pub struct Envelope {
    limits: SafetyEnvelope,
    margins: PlanningMargins,
    capsules: [Capsule; ARM_CAPSULES],
    stop_capsules: [Capsule; ARM_CAPSULES],
    fk: CapsuleCache,
    speed: Option<([u64; 12], f64)>,
    memo: [Option<(MemoKey, Admissible)>; 2],
    /// The memo slot replaced next (the one not used last).
    memo_next: usize,
    /// Per body part: the closest approaches (now, at the stop) for the arm at the joints and
    /// stop joints and the part's capsule of the key. The predicted body differs from the body
    /// now only in its extrapolated points: the others reuse these.
    parts: [Option<PartApproaches>; 4],
}

/// The closest approaches of one body part for an exact key: the joint bits now and at the
/// stop, and the part's capsule's bits.
type PartApproaches = ([u64; 19], Option<Approach>, Option<Approach>);

fn part_key(q: &[u64; 6], q_stop: &[u64; 6], c: &Capsule) -> [u64; 19] {
    let mut k = [0_u64; 19];
    let values = q.iter().chain(q_stop).copied().chain(
        c.a_m
            .iter()
            .chain(&c.b_m)
            .chain(std::iter::once(&c.radius_m))
            .map(|v| v.to_bits()),
    );
    for (slot, v) in k.iter_mut().zip(values) {
        *slot = v;
    }
    k
}

/// `body` without `part`.
fn without(mut body: HumanBody, part: BodyPart) -> HumanBody {
    match part {
        BodyPart::Head => body.head_m = None,
        BodyPart::LeftHand => body.left_hand_m = None,
        BodyPart::RightHand => body.right_hand_m = None,
        BodyPart::Torso => body.torso = None,
    }
    body
}

/// The bits of a joint vector (an exact cache key: equal bits, equal results).
fn joint_bits(q: &Joints) -> [u64; 6] {
    q.map(f64::to_bits)
}

/// The arm capsules of the two latest joint positions (exact: the same bits give the same
/// capsules).
#[derive(Debug, Clone)]
struct CapsuleCache {
    slots: [Option<([u64; 6], [Capsule; ARM_CAPSULES])>; 2],
    next: usize,
}

impl CapsuleCache {
    /// `out` = `arm`'s capsules at `q`, from the cache when `q` was among the two latest.
    fn capsules(&mut self, arm: &ArmModel, q: &Joints, out: &mut [Capsule; ARM_CAPSULES]) {
        let key = joint_bits(q);
        for (k, c) in self.slots.iter().flatten() {
            if *k == key {
                *out = *c;
                return;
            }
        }
        arm.capsules(q, out);
        if let Some(slot) = self.slots.get_mut(self.next) {
            *slot = Some((key, *out));
        }
        self.next = (self.next + 1) % 2;
    }
}

/// Everything [`Envelope::admissible_scale`]'s result depends on, as bits: joints, path
/// velocity, the body (a presence mask, then the values), the planning perception age
/// (`max(age, margin)`) and the flags stale and collaborating.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct MemoKey([u64; 30]);

impl MemoKey {
    fn new(q: &Joints, qd: &Joints, body: &HumanBody, age: f64, stale: bool, collab: bool) -> Self {
        let mut w = [0_u64; 30];
        let none = [0.0; 3];
        let torso = body.torso;
        let points = [
            body.head_m,
            body.left_hand_m,
            body.right_hand_m,
            torso.map(|t| t.shoulder_mid_m),
            torso.map(|t| t.normal),
        ];
        let mut mask = u64::from(stale) | (u64::from(collab) << 1);
        let values = q
            .iter()
            .chain(qd)
            .copied()
            .chain(points.iter().flat_map(|p| p.unwrap_or(none)))
            .chain(std::iter::once(age));
        for (slot, v) in w.iter_mut().zip(values) {
            *slot = v.to_bits();
        }
        for (i, p) in points.iter().enumerate() {
            if p.is_some() {
                mask |= 1 << (2 + i);
            }
        }
        if let Some(last) = w.last_mut() {
            *last = mask;
        }
        MemoKey(w)
    }
}

/// The flange speed |J(q)·q'| [m/s] for joint velocity `qd` [rad/s] at `q` [rad], by a central
/// difference of the forward kinematics over ±1e-5 rad on the fastest joint (exact to ~1e-10
/// relative for the smooth UR5e kinematics).
pub fn flange_speed_m_s(q: &Joints, qd: &Joints) -> f64 {
    let fastest = qd.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    if !(fastest.is_finite() && fastest > 0.0) {
        return if fastest.is_finite() { 0.0 } else { f64::NAN };
    }
    let h = 1e-5 / fastest;
    let mut plus = *q;
    let mut minus = *q;
    for ((p, m), v) in plus.iter_mut().zip(minus.iter_mut()).zip(qd) {
        *p += v * h;
        *m -= v * h;
    }
    let a = flange_pose(&plus).translation.vector;
    let b = flange_pose(&minus).translation.vector;
    (a - b).norm() / (2.0 * h)
}

impl Envelope {
    /// An evaluator for `limits` with `margins`.
    pub fn new(limits: SafetyEnvelope, margins: PlanningMargins) -> Envelope {
        let zero = Capsule {
            a_m: [0.0; 3],
            b_m: [0.0; 3],
            radius_m: 0.0,
        };
        Envelope {
            limits,
            margins,
            capsules: [zero; ARM_CAPSULES],
            stop_capsules: [zero; ARM_CAPSULES],
            fk: CapsuleCache {
                slots: [None; 2],
                next: 0,
            },
            speed: None,
            memo: [None; 2],
            memo_next: 0,
            parts: [None; 4],
        }
    }

    /// The supervisor's limits in use.
    pub fn limits(&self) -> &SafetyEnvelope {
        &self.limits
    }

    /// The margins in use.
    pub fn margins(&self) -> &PlanningMargins {
        &self.margins
    }

    /// The TCP cap the planner plans under [m/s]: the planning fraction of the supervisor's
    /// cap (its collaboration value while `collaborating`).
    pub fn planned_tcp_cap_m_s(&self, collaborating: bool) -> f64 {
        let cap = if collaborating {
            self.limits.collaboration_tcp_speed_m_s
        } else {
            self.limits.tcp_speed_m_s
        };
        self.margins.raw.speed_fraction * cap
    }

    /// The largest admissible scale at joints `q` [rad] moving along the path with velocity
    /// `qd_path` [rad/s] (at s = 1), with the operator at `body` (base frame), perception
    /// `perception_age_s` [s] old, while `collaborating` (C(t)). See the module docs.
    pub fn admissible_scale(
        &mut self,
        q: &Joints,
        qd_path: &Joints,
        body: &HumanBody,
        perception_age_s: f64,
        collaborating: bool,
    ) -> Admissible {
        let invalid = Admissible {
            scale: 0.0,
            binding: Binding::Invalid,
            min_distance_m: f64::NAN,
        };
        if !(q.iter().chain(qd_path).all(|v| v.is_finite()) && perception_age_s.is_finite()) {
            return invalid;
        }
        let m = self.margins.raw;
        let l = self.limits;
        let stale = perception_age_s > l.perception_reduce_after_s;
        // The perception age grows by a frame period between frames and drops at each new one;
        // planning with at least the margin keeps the admissible scale from following that
        // saw-tooth (the supervisor uses the actual age, never above it in nominal operation).
        let age = perception_age_s.max(m.perception_age_margin_s);
        let key = MemoKey::new(q, qd_path, body, age, stale, collaborating);
        for (i, slot) in self.memo.iter().enumerate() {
            if let Some((k, a)) = slot
                && *k == key
            {
                self.memo_next = 1 - i.min(1);
                return *a;
            }
        }
        let a = self.evaluate(q, qd_path, body, age, stale, collaborating);
        if let Some(slot) = self.memo.get_mut(self.memo_next) {
            *slot = Some((key, a));
        }
        self.memo_next = 1 - self.memo_next.min(1);
        a
    }

    /// [`Envelope::admissible_scale`] without its memo (inputs finite; `age` the planning
    /// age, `stale` whether the stale-perception scale applies).
    fn evaluate(
        &mut self,
        q: &Joints,
        qd_path: &Joints,
        body: &HumanBody,
        age: f64,
        stale: bool,
        collaborating: bool,
    ) -> Admissible {
        let invalid = Admissible {
            scale: 0.0,
            binding: Binding::Invalid,
            min_distance_m: f64::NAN,
        };
        let m = self.margins.raw;
        let l = self.limits;
        let k = if stale { l.stale_perception_scale } else { 1.0 };
        let w = qd_path.iter().fold(0.0_f64, |a, x| a.max(x.abs()));
        let speed_key = {
            let mut b = [0_u64; 12];
            for (slot, v) in b.iter_mut().zip(q.iter().chain(qd_path)) {
                *slot = v.to_bits();
            }
            b
        };
        let u = match self.speed {
            Some((k, u)) if k == speed_key => u,
            _ => {
                let u = flange_speed_m_s(q, qd_path);
                self.speed = Some((speed_key, u));
                u
            }
        };
        if !u.is_finite() {
            return invalid;
        }
        let mut best = Admissible {
            scale: 1.0,
            binding: Binding::None,
            min_distance_m: f64::INFINITY,
        };
        let bind = |s: f64, b: Binding, best: &mut Admissible| {
            if s < best.scale {
                best.scale = s.max(0.0);
                best.binding = b;
            }
        };
        if w > 0.0 {
            bind(
                m.speed_fraction * l.joint_speed_rad_s * k / w,
                Binding::JointSpeed,
                &mut best,
            );
        }
        if u > 0.0 {
            bind(
                self.planned_tcp_cap_m_s(collaborating) * k / u,
                Binding::TcpSpeed,
                &mut best,
            );
        }
        if !BodyPart::ALL.iter().any(|p| body.tracks(*p)) {
            // Nobody tracked: no separation limit (and no capsule to compute).
            best.scale = best.scale.clamp(0.0, 1.0);
            return best;
        }
        // Separation: distances now and at the supervisor's stopping configuration (for the
        // current scale bound, at which the robot would run).
        self.fk.capsules(&l.arm, q, &mut self.capsules);
        let s_run = best.scale;
        let t_stop = (1.0 + m.measured_speed_allowance) * s_run * w / l.stop_deceleration_rad_s2;
        let mut q_stop = *q;
        for (qs, v) in q_stop.iter_mut().zip(qd_path) {
            *qs += s_run * v * t_stop / 2.0;
        }
        self.fk.capsules(&l.arm, &q_stop, &mut self.stop_capsules);
        // Parts whose approaches are cached for these joints are left out of the search.
        let (q_key, stop_key) = (joint_bits(q), joint_bits(&q_stop));
        let mut todo = *body;
        let mut keys = [None; 4];
        let mut cached = [None; 4];
        for (((part, key), hit), slot) in BodyPart::ALL
            .iter()
            .zip(&mut keys)
            .zip(&mut cached)
            .zip(&self.parts)
        {
            let Some(c) = l.body.capsule(body, *part) else {
                continue;
            };
            let k = part_key(&q_key, &stop_key, &c);
            match slot {
                Some((sk, a, b)) if *sk == k => {
                    *hit = Some((*a, *b));
                    todo = without(todo, *part);
                }
                _ => *key = Some(k),
            }
        }
        let mut now = closest_approaches(&self.capsules, &todo, &l.body);
        let mut stop = closest_approaches(&self.stop_capsules, &todo, &l.body);
        for ((((a, b), key), hit), slot) in now
            .iter_mut()
            .zip(&mut stop)
            .zip(&keys)
            .zip(&cached)
            .zip(&mut self.parts)
        {
            if let Some((ca, cb)) = hit {
                (*a, *b) = (*ca, *cb);
            } else if let Some(k) = key {
                *slot = Some((*k, *a, *b));
            }
        }
        let eps = 1.0 + m.measured_speed_allowance;
        for ((part, a), b) in BodyPart::ALL.iter().zip(&now).zip(&stop) {
            let d = match (a, b) {
                (Some(a), Some(b)) => a.distance_m.min(b.distance_m),
                (Some(a), None) => a.distance_m,
                (None, Some(b)) => b.distance_m,
                (None, None) => continue,
            };
            if d.is_nan() {
                return invalid;
            }
            best.min_distance_m = best.min_distance_m.min(d);
            // S_p(s) = c0 + c1 s + c2 s², from the shared formula at s = 0, ½, 1.
            let sp = |s: f64| {
                let v_r = eps * s * u;
                let t_s = eps * s * w / l.stop_deceleration_rad_s2;
                protective_distance_m(&l.separation, *part, v_r, t_s, age)
            };
            let (f0, fh, f1) = (sp(0.0), sp(0.5), sp(1.0));
            let c0 = f0;
            let c2 = 2.0 * (f1 - 2.0 * fh + f0);
            let c1 = f1 - f0 - c2;
            let s = largest_root_below(c0, c1.max(0.0), c2.max(0.0), d - m.distance_margin_m);
            bind(s, Binding::Separation(*part), &mut best);
        }
        best.scale = best.scale.clamp(0.0, 1.0);
        best
    }
}

/// The largest `s ≥ 0` with `c0 + c1 s + c2 s² ≤ limit` for `c1, c2 ≥ 0` (the quadratic is
/// increasing): 0 when even `s = 0` breaks it, +∞ when nothing grows with `s`.
pub fn largest_root_below(c0: f64, c1: f64, c2: f64, limit: f64) -> f64 {
    let gamma = c0 - limit;
    if !(gamma.is_finite() && c1.is_finite() && c2.is_finite()) || gamma >= 0.0 {
        return 0.0;
    }
    let disc = c1 * c1 - 4.0 * c2 * gamma; // ≥ c1² since γ < 0
    let den = c1 + disc.sqrt();
    if den <= 0.0 {
        return f64::INFINITY;
    }
    -2.0 * gamma / den
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn largest_root_matches_a_hand_computed_quadratic() {
        // Worked example (by hand): 0.4 + 0.5 s + 0.25 s² ≤ 1.0 ⇔ 0.25 s² + 0.5 s − 0.6 ≤ 0:
        // s = (−0.5 + √(0.25 + 0.6)) / 0.5 = (−0.5 + 0.921954) / 0.5 = 0.843909.
        let s = largest_root_below(0.4, 0.5, 0.25, 1.0);
        assert!((s - 0.843_908_9).abs() < 1e-6, "{s}");
        // Linear: 0.4 + 0.5 s ≤ 1 ⇒ s = 1.2.
        assert!((largest_root_below(0.4, 0.5, 0.0, 1.0) - 1.2).abs() < 1e-12);
        // Inside already: 0.
        assert_eq!(largest_root_below(1.1, 0.5, 0.25, 1.0), 0.0);
        assert_eq!(largest_root_below(f64::NAN, 0.5, 0.25, 1.0), 0.0);
        assert_eq!(largest_root_below(0.4, 0.0, 0.0, 1.0), f64::INFINITY);
    }

    #[test]
    fn flange_speed_matches_a_finite_difference_of_the_pose() {
        let q = [0.3, -1.2, 1.1, -1.4, -1.5, 0.2];
        let qd = [0.2, -0.1, 0.3, 0.0, 0.1, -0.4];
        let dt = 1e-7;
        let mut q2 = q;
        for (a, v) in q2.iter_mut().zip(&qd) {
            *a += v * dt;
        }
        let a = flange_pose(&q).translation.vector;
        let b = flange_pose(&q2).translation.vector;
        let reference = (b - a).norm() / dt;
        let u = flange_speed_m_s(&q, &qd);
        assert!(
            (u - reference).abs() < 1e-5 * reference.max(1e-3),
            "{u} vs {reference}"
        );
        assert_eq!(flange_speed_m_s(&q, &[0.0; 6]), 0.0);
    }
}
