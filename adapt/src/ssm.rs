//! Speed and separation monitoring (SSM) and power-and-force-limiting (PFL) speed limits,
//! after ISO/TS 15066 and Marvel & Norcross (2017).
//!
//! # Protective separation distance
//!
//! ```text
//! S_p = S_h + S_r + S_s + C + Z_d + Z_r
//! S_h = v_h (T_r + T_s)      human travel while the robot reacts and stops   [m]
//! S_r = v_r T_r              robot travel during its reaction time           [m]
//! S_s = v_r² / (2 a_b)       robot stopping distance at braking deceleration [m]
//! T_s = v_r / a_b            robot stopping time                             [s]
//! C, Z_d, Z_r                intrusion distance, human and robot position uncertainty [m]
//! ```
//! with `v_h` = 1.6 m/s (walking, used for the head) or 2.0 m/s (arm reach, used for the hands),
//! as in ISO 13855; `v_r` the robot speed toward the human point; `T_r` the reaction time of the
//! whole chain (perception latency + control cycle + robot); `a_b` the braking deceleration of the
//! control point.
//!
//! # Largest admissible robot speed at distance d
//!
//! `S_s` and `S_h` both depend on `v_r` through the stopping time, so `S_p ≤ d` is a quadratic
//! inequality in `v = v_r`:
//!
//! ```text
//! S_p(v) = v_h T_r + v_h v / a_b + v T_r + v² / (2 a_b) + C + Z_d + Z_r
//!        = α v² + β v + (v_h T_r + C + Z_d + Z_r)
//!   α = 1 / (2 a_b)          [s²/m]
//!   β = T_r + v_h / a_b      [s]
//! S_p(v) ≤ d  ⇔  α v² + β v + γ ≤ 0,   γ = v_h T_r + C + Z_d + Z_r − d   [m]
//! ```
//! `S_p` is increasing in `v ≥ 0` (α, β > 0). If `γ > 0` the human is already inside the
//! protective distance with the robot at rest, and the only admissible speed is 0. Otherwise the
//! admissible set is `0 ≤ v ≤ v*`, with `v*` the positive root
//!
//! ```text
//! v* = (−β + √(β² − 4 α γ)) / (2 α)  =  −2 γ / (β + √(β² − 4 α γ))
//! ```
//! The second form is the one computed: it has no cancellation when `|4 α γ| ≪ β²` (far from
//! the human, or a high braking deceleration). As `a_b → ∞` it tends to `(d − v_h T_r − C − Z)/T_r`,
//! the linear limit without a stopping distance.
//!
//! # Transient-contact (PFL) limit
//!
//! For a body region where contact is allowed, ISO/TS 15066 Annex A bounds the relative speed by
//! the energy the region can absorb:
//!
//! ```text
//! v_max = F_max / √k · √(1/m_H + 1/m_R),    m_R = M/2 + m_L
//! ```
//! with `k` the effective spring constant of the region (N/m; the standard tabulates N/mm),
//! `m_H` its effective mass, `M` the mass of the moving parts of the robot and `m_L` the payload.
//! For the hand (k = 75 N/mm, m_H = 0.6 kg, F = 140 N quasi-static, 280 N transient) on a UR5e
//! (M ≈ 17.7 kg, m_L = 5 kg): 1.348 m/s transient and 0.674 m/s quasi-static. Issue 4 quotes
//! ≈ 1.36 and ≈ 0.68 m/s: those are the values without the payload (m_L = 0, m_R = 8.85 kg:
//! 1.364 and 0.682 m/s); see the worked example in `tests/ssm.rs`.

use crate::{AdaptError, Result};

/// Which part of the operator a tracked point is. It selects the human approach speed `v_h`
/// and whether contact is allowed (PFL).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HumanPointKind {
    /// The head: walking speed (1.6 m/s), contact never allowed.
    Head,
    /// A hand: arm-reach speed (2.0 m/s), transient contact allowed inside `d_contact`.
    Hand,
}

/// A speed limit in m/s: finite and ≥ 0.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct SpeedLimit(f64);

impl SpeedLimit {
    /// A speed limit of `m_s` m/s; finite and ≥ 0, else an error.
    pub fn new(m_s: f64) -> Result<Self> {
        if m_s.is_finite() && m_s >= 0.0 {
            Ok(Self(m_s))
        } else {
            Err(AdaptError::InvalidSafetyParameter {
                name: "speed_limit_m_s",
                value: m_s,
                rule: "must be finite and >= 0",
            })
        }
    }

    /// The limit in m/s.
    pub fn m_s(self) -> f64 {
        self.0
    }
}

/// Raw SSM and PFL parameters, as read from config (units in the names). Validate them with
/// [`SsmConfig::try_from`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SsmParams {
    /// Human walking speed `v_h` for the head, m/s (ISO 13855: 1.6).
    pub walking_speed_m_s: f64,
    /// Human arm-reach speed `v_h` for the hands, m/s (ISO 13855: 2.0).
    pub arm_reach_speed_m_s: f64,
    /// Reaction time `T_r` of perception + control + robot, s.
    pub reaction_time_s: f64,
    /// Braking deceleration `a_b` of a robot control point, m/s²; `S_s = v²/(2 a_b)`.
    pub braking_deceleration_m_s2: f64,
    /// Intrusion distance `C`, m (≥ 0).
    pub intrusion_distance_m: f64,
    /// Human position uncertainty `Z_d`, m (≥ 0).
    pub human_uncertainty_m: f64,
    /// Robot position uncertainty `Z_r`, m (≥ 0).
    pub robot_uncertainty_m: f64,
    /// Hands closer than this to a control point are in the PFL contact zone, m (≥ 0).
    pub contact_distance_m: f64,
    /// Effective spring constant of the hand, N/mm (ISO/TS 15066: 75).
    pub hand_stiffness_n_per_mm: f64,
    /// Effective mass of the hand `m_H`, kg (ISO/TS 15066: 0.6).
    pub hand_mass_kg: f64,
    /// Quasi-static contact force limit for the hand, N (ISO/TS 15066: 140).
    pub hand_quasi_static_force_n: f64,
    /// Transient contact force limit for the hand, N (ISO/TS 15066: 280 = 2 × 140).
    pub hand_transient_force_n: f64,
    /// Mass of the moving parts of the robot `M`, kg (UR5e: ≈ 17.7).
    pub robot_moving_mass_kg: f64,
    /// Payload `m_L`, kg (UR5e rating: 5).
    pub payload_kg: f64,
}

impl Default for SsmParams {
    /// ISO 13855 / ISO/TS 15066 values for a UR5e with its rated payload; reaction time 0.1 s,
    /// braking 2.5 m/s², C = 0.1 m, Z_d = 0.05 m, Z_r = 0.01 m, d_contact = 0.15 m.
    fn default() -> Self {
        Self {
            walking_speed_m_s: 1.6,
            arm_reach_speed_m_s: 2.0,
            reaction_time_s: 0.1,
            braking_deceleration_m_s2: 2.5,
            intrusion_distance_m: 0.1,
            human_uncertainty_m: 0.05,
            robot_uncertainty_m: 0.01,
            contact_distance_m: 0.15,
            hand_stiffness_n_per_mm: 75.0,
            hand_mass_kg: 0.6,
            hand_quasi_static_force_n: 140.0,
            hand_transient_force_n: 280.0,
            robot_moving_mass_kg: 17.7,
            payload_kg: 5.0,
        }
    }
}

/// Validated SSM and PFL parameters: every value finite; speeds, times, the deceleration,
/// stiffness, masses and forces > 0; distances and the payload ≥ 0. The default is
/// [`SsmParams::default`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SsmConfig {
    p: SsmParams,
}

fn check(name: &'static str, value: f64, strictly_positive: bool) -> Result<()> {
    let ok = value.is_finite()
        && if strictly_positive {
            value > 0.0
        } else {
            value >= 0.0
        };
    if ok {
        Ok(())
    } else {
        Err(AdaptError::InvalidSafetyParameter {
            name,
            value,
            rule: if strictly_positive {
                "must be finite and > 0"
            } else {
                "must be finite and >= 0"
            },
        })
    }
}

impl TryFrom<SsmParams> for SsmConfig {
    type Error = AdaptError;

    fn try_from(p: SsmParams) -> Result<Self> {
        check("walking_speed_m_s", p.walking_speed_m_s, true)?;
        check("arm_reach_speed_m_s", p.arm_reach_speed_m_s, true)?;
        check("reaction_time_s", p.reaction_time_s, true)?;
        check(
            "braking_deceleration_m_s2",
            p.braking_deceleration_m_s2,
            true,
        )?;
        check("intrusion_distance_m", p.intrusion_distance_m, false)?;
        check("human_uncertainty_m", p.human_uncertainty_m, false)?;
        check("robot_uncertainty_m", p.robot_uncertainty_m, false)?;
        check("contact_distance_m", p.contact_distance_m, false)?;
        check("hand_stiffness_n_per_mm", p.hand_stiffness_n_per_mm, true)?;
        check("hand_mass_kg", p.hand_mass_kg, true)?;
        check(
            "hand_quasi_static_force_n",
            p.hand_quasi_static_force_n,
            true,
        )?;
        check("hand_transient_force_n", p.hand_transient_force_n, true)?;
        check("robot_moving_mass_kg", p.robot_moving_mass_kg, true)?;
        check("payload_kg", p.payload_kg, false)?;
        Ok(Self { p })
    }
}

impl SsmConfig {
    /// The validated parameters.
    pub fn params(&self) -> &SsmParams {
        &self.p
    }

    /// The human approach speed `v_h` for a point kind, m/s.
    pub fn human_speed_m_s(&self, kind: HumanPointKind) -> f64 {
        match kind {
            HumanPointKind::Head => self.p.walking_speed_m_s,
            HumanPointKind::Hand => self.p.arm_reach_speed_m_s,
        }
    }

    /// Distance below which hands are in the PFL contact zone, m.
    pub fn contact_distance_m(&self) -> f64 {
        self.p.contact_distance_m
    }

    /// Robot stopping distance `S_s = v² / (2 a_b)` from speed `robot_speed_m_s`, m.
    pub fn stopping_distance_m(&self, robot_speed_m_s: f64) -> f64 {
        let v = robot_speed_m_s.max(0.0);
        v * v / (2.0 * self.p.braking_deceleration_m_s2)
    }

    /// Protective separation distance `S_p` (m) for a robot moving toward a human point of
    /// `kind` at `robot_speed_m_s` (m/s, negative treated as 0).
    pub fn protective_distance_m(&self, kind: HumanPointKind, robot_speed_m_s: f64) -> f64 {
        let p = &self.p;
        let v = robot_speed_m_s.max(0.0);
        let stop_time_s = v / p.braking_deceleration_m_s2;
        let s_h = self.human_speed_m_s(kind) * (p.reaction_time_s + stop_time_s);
        let s_r = v * p.reaction_time_s;
        let s_s = self.stopping_distance_m(v);
        s_h + s_r + s_s + p.intrusion_distance_m + p.human_uncertainty_m + p.robot_uncertainty_m
    }

    /// The largest robot speed toward a human point of `kind` at distance `distance_m` (m)
    /// such that `S_p ≤ d`, in m/s (the positive root derived in the module docs; 0 when the
    /// point is already inside the protective distance, or when `distance_m` is not finite).
    pub fn separation_speed_limit_m_s(&self, kind: HumanPointKind, distance_m: f64) -> f64 {
        if !distance_m.is_finite() {
            // NaN: unknown distance, stop. +inf: no human; still bounded by nothing here, but the
            // caller never passes +inf (absent humans are `None`); be conservative.
            return 0.0;
        }
        let p = &self.p;
        let v_h = self.human_speed_m_s(kind);
        let a_b = p.braking_deceleration_m_s2;
        let alpha = 0.5 / a_b;
        let beta = p.reaction_time_s + v_h / a_b;
        let gamma = v_h * p.reaction_time_s
            + p.intrusion_distance_m
            + p.human_uncertainty_m
            + p.robot_uncertainty_m
            - distance_m;
        if gamma >= 0.0 {
            return 0.0;
        }
        let disc = beta * beta - 4.0 * alpha * gamma; // > β² since γ < 0
        let v = -2.0 * gamma / (beta + disc.sqrt());
        if v.is_finite() { v.max(0.0) } else { 0.0 }
    }

    /// The effective robot mass `m_R = M/2 + m_L`, kg.
    pub fn effective_robot_mass_kg(&self) -> f64 {
        0.5 * self.p.robot_moving_mass_kg + self.p.payload_kg
    }

    /// PFL speed limit for the hand at contact force `force_n` (N):
    /// `F/√k · √(1/m_H + 1/m_R)`, with `k` converted from N/mm to N/m; m/s.
    pub fn hand_contact_speed_m_s(&self, force_n: f64) -> f64 {
        let k_n_per_m = self.p.hand_stiffness_n_per_mm * 1000.0;
        let inv_mu = 1.0 / self.p.hand_mass_kg + 1.0 / self.effective_robot_mass_kg();
        force_n / k_n_per_m.sqrt() * inv_mu.sqrt()
    }

    /// Transient-contact speed limit for the hand (F = `hand_transient_force_n`), m/s.
    pub fn hand_transient_speed_m_s(&self) -> f64 {
        self.hand_contact_speed_m_s(self.p.hand_transient_force_n)
    }

    /// Quasi-static-contact speed limit for the hand (F = `hand_quasi_static_force_n`), m/s.
    pub fn hand_quasi_static_speed_m_s(&self) -> f64 {
        self.hand_contact_speed_m_s(self.p.hand_quasi_static_force_n)
    }

    /// The speed limit (m/s) that speed scaling applies to the velocity of a robot control point
    /// toward a human point of `kind` at `distance_m`:
    /// - a hand inside `contact_distance_m`: transient contact is allowed (PFL), so the limit is
    ///   the transient-contact speed (the SSM limit is 0 that close, which would forbid a handover);
    /// - otherwise the SSM separation-speed limit.
    pub fn approach_speed_limit_m_s(&self, kind: HumanPointKind, distance_m: f64) -> f64 {
        match kind {
            HumanPointKind::Hand
                if distance_m.is_finite() && distance_m <= self.p.contact_distance_m =>
            {
                self.hand_transient_speed_m_s()
            }
            _ => self.separation_speed_limit_m_s(kind, distance_m),
        }
    }
}
