//! Per-cycle QP speed scaling near the human.
//!
//! # Problem
//!
//! Every 2 ms cycle, given the reference joint velocity `r = q̇_ref` from the trajectory generator,
//! [`SpeedScaler::solve`] computes
//!
//! ```text
//! q̇ = argmin ½‖q̇ − r‖² + ρ Σᵢ sᵢ
//!     subject to  lo ≤ q̇ ≤ hi                                   (hard)
//!                 aᵢᵀ q̇ ≤ bᵢ + sᵢ,  0 ≤ sᵢ ≤ uᵢ,  i = 1..m       (soft, L1-penalised slack)
//! lo_j = max(−v_max,j, q̇_prev,j − a_max,j dt),  hi_j = min(v_max,j, q̇_prev,j + a_max,j dt)
//! ```
//! The box is the intersection of the joint velocity limits and the acceleration limits
//! `|q̇ − q̇_prev| ≤ a·dt`. If `q̇_prev` is outside the velocity limits by more than one
//! acceleration step the box would be empty; the velocity limit wins and the joint is pinned at
//! `clamp(q̇_prev, −v_max, v_max)`.
//!
//! The linear rows `aᵢᵀ q̇ ≤ bᵢ` are:
//! - **separation**: for every tracked human point `h` (head, both hands) and robot control point
//!   `p` (TCP, wrist, elbow), the speed of `p` toward `h`, `n̂ᵀ J_p q̇` with `n̂ = (h − p)/‖h − p‖`,
//!   is at most [`SsmConfig::approach_speed_limit_m_s`] (SSM limit; transient-contact PFL limit for
//!   a hand inside `d_contact`). If `h` and `p` coincide, `n̂` is the direction of `J_p r`.
//!   Rows whose limit cannot bind anywhere in the box are dropped.
//! - **TCP speed cap** from the adaptation: `‖J_tcp q̇‖ ≤ cap` is not linear. The reference is first
//!   scaled uniformly (which keeps the path) so that `‖J_tcp r‖ ≤ cap`, and the cap is linearised
//!   along the direction of the reference, `ûᵀ J_tcp q̇ ≤ cap` with `û = J_tcp r/‖J_tcp r‖`. When no
//!   other row is active the solution is the scaled reference and the cap holds exactly; when
//!   separation rows bend the velocity, only the component along `û` is capped (the correction
//!   itself only ever reduces approach speeds). The supervisor checks the true TCP speed.
//!
//! Every row is normalised (`‖aᵢ‖ = 1`), so `bᵢ`, `sᵢ` and `ρ` are in rad/s. All `bᵢ ≥ 0`,
//! so `q̇ = 0` satisfies every row: infeasibility only ever comes from the acceleration box, when
//! one step cannot bring an approach speed under its limit. The L1 penalty is exact: when the hard
//! problem is feasible and ρ exceeds its largest multiplier, the slack is zero; when it is not, the
//! solution minimises the violation, i.e. brakes toward the limit as hard as the box allows.
//! The slack is capped, `uᵢ = max(0, aᵢᵀ q̇_brake − bᵢ)` with `q̇_brake` the braking fallback (below):
//! a row may stay violated, but never by more than braking would leave it. `q̇_brake` lies in the
//! box and meets every capped row, so the penalised problem is always feasible.
//!
//! # Solver (real-time path)
//!
//! [`SpeedScaler`] solves the problem itself, allocation-free, with fixed-size arrays:
//! 1. If the box projection `clip(r, lo, hi)` meets every row, it is optimal (most cycles).
//! 2. Otherwise, dual coordinate ascent: the dual of the penalised problem is
//!    `max_{λ ≥ 0} min_{lo ≤ x ≤ hi} ½‖x − r‖² + λᵀ(Ax − b) − Σᵢ max(0, λᵢ − ρ) uᵢ`
//!    (a row's multiplier exceeds ρ only once its slack is exhausted), whose inner minimiser is
//!    `x(λ) = clip(r − Aᵀλ, lo, hi)`. Each coordinate step maximises exactly over one `λᵢ`:
//!    that is the closed-form projection onto the box and one half-space,
//!    [`project_box_halfspace`] (a monotone piecewise-linear root, found by walking the ≤ 12
//!    breakpoints). With one row, one step is the exact solution.
//! 3. Sweeps stop when the KKT conditions hold to `tolerance_rad_s`, or after `max_sweeps`
//!    ([`QpStatus::TimeLimit`]).
//!
//! # Fallback and safety check
//!
//! The braking fallback scales `q̇_prev` uniformly toward zero as fast as the acceleration limits
//! allow (the path is kept and every approach speed shrinks by the same factor). A slack or
//! time-limited solution is used only if, for every row it violates, it approaches no faster than
//! the braking fallback; otherwise the fallback is used ([`QpStatus::Infeasible`]). Non-finite or
//! negative inputs give [`QpStatus::InvalidInput`] and the fallback (zero velocity if `q̇_prev`,
//! the limits or `dt` themselves are unusable). `solve` never panics.
//!
//! [`ClarabelSpeedScaler`] poses the same problem to clarabel (in-place updates, presolve off)
//! as a cross-check. Clarabel 0.11.1 allocates inside every `solve` (its internal timers rebuild
//! a `HashMap` per solve), so it is not used in the 500 Hz cycle.

use crate::ssm::{HumanPointKind, SsmConfig};
use crate::{AdaptError, Result};

/// Number of joints.
pub const N_JOINTS: usize = 6;
/// Number of robot control points: TCP (index 0), wrist (1), elbow (2).
pub const N_CONTROL_POINTS: usize = 3;
/// Number of tracked human points: head and both hands.
pub const N_HUMAN_POINTS: usize = 3;
/// Largest number of linear rows: one per (control point, human point) pair, plus the TCP cap.
pub const MAX_ROWS: usize = N_CONTROL_POINTS * N_HUMAN_POINTS + 1;

const EPS_NORM: f64 = 1e-12;

/// A robot control point: its position and its linear-velocity Jacobian, both in the robot base
/// frame (the frame of the human points).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ControlPointInput {
    /// Position, m.
    pub position: [f64; 3],
    /// Linear-velocity Jacobian: row k is d(position k)/dq, m/rad; velocity = J q̇ (m/s).
    pub jacobian: [[f64; N_JOINTS]; 3],
}

/// A tracked human point, in the robot base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HumanPoint {
    /// Position, m.
    pub position: [f64; 3],
    /// Head or hand: selects the approach speed and whether contact is allowed.
    pub kind: HumanPointKind,
}

/// Everything one cycle of speed scaling needs, as plain data.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct QpInput {
    /// Reference joint velocity from the trajectory generator, rad/s.
    pub qd_ref: [f64; N_JOINTS],
    /// Joint velocity commanded in the previous cycle, rad/s.
    pub qd_prev: [f64; N_JOINTS],
    /// Cycle period, s (> 0; 0.002 on a UR5e).
    pub dt_s: f64,
    /// Joint velocity limits, rad/s (≥ 0).
    pub max_velocity: [f64; N_JOINTS],
    /// Joint acceleration limits, rad/s² (≥ 0).
    pub max_acceleration: [f64; N_JOINTS],
    /// TCP speed cap from the adaptation, m/s (≥ 0; `f64::INFINITY` for none).
    pub tcp_speed_cap_m_s: f64,
    /// TCP (index 0), wrist (1) and elbow (2).
    pub control_points: [ControlPointInput; N_CONTROL_POINTS],
    /// Head and hands; `None` when not tracked this cycle.
    pub humans: [Option<HumanPoint>; N_HUMAN_POINTS],
}

/// Outcome of one cycle. The output velocity is always finite and within the velocity limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QpStatus {
    /// Optimal; every separation and cap row holds (to the tolerance).
    Solved,
    /// The rows could not all be met within one acceleration step; the penalised solution
    /// (least violation) is used. It approaches no violated point faster than braking would.
    SolvedWithSlack,
    /// The penalised solution would have approached a violated point faster than braking, so
    /// the braking fallback (`q̇_prev` scaled toward 0 within the acceleration limits) is used.
    Infeasible,
    /// The sweep budget ran out; the last iterate is used (it is within the box, and each row
    /// holds or is no worse than braking), else the braking fallback.
    TimeLimit,
    /// An input was non-finite or negative where it must not be; the braking fallback is used
    /// (zero velocity if `qd_prev`, the limits or `dt_s` are themselves unusable).
    InvalidInput,
}

impl QpStatus {
    /// True if the output is the braking fallback rather than a solution.
    pub fn is_fallback(self) -> bool {
        matches!(self, Self::Infeasible | Self::InvalidInput)
    }
}

/// Raw solver parameters (units in the names). Validate with [`QpConfig::new`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QpParams {
    /// L1 slack penalty ρ on the normalised rows, rad/s (> 0). Must exceed the largest multiplier
    /// of a feasible problem for the penalty to be exact; 1e3 is far above any real case.
    pub slack_penalty_rad_s: f64,
    /// KKT and feasibility tolerance on the normalised rows, rad/s (> 0).
    pub tolerance_rad_s: f64,
    /// Coordinate-ascent sweep budget per cycle (≥ 1).
    pub max_sweeps: u32,
}

impl Default for QpParams {
    fn default() -> Self {
        Self {
            slack_penalty_rad_s: 1e3,
            tolerance_rad_s: 1e-7,
            max_sweeps: 500,
        }
    }
}

/// Validated speed-scaling configuration: the SSM/PFL limits and the solver parameters.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct QpConfig {
    ssm: SsmConfig,
    params: QpParams,
}

impl QpConfig {
    /// Validates `params` (penalty and tolerance finite and > 0, at least one sweep).
    pub fn new(ssm: SsmConfig, params: QpParams) -> Result<Self> {
        let positive = |name: &'static str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(AdaptError::InvalidSafetyParameter {
                    name,
                    value: v,
                    rule: "must be finite and > 0",
                })
            }
        };
        positive("slack_penalty_rad_s", params.slack_penalty_rad_s)?;
        positive("tolerance_rad_s", params.tolerance_rad_s)?;
        if params.max_sweeps == 0 {
            return Err(AdaptError::InvalidSafetyParameter {
                name: "max_sweeps",
                value: 0.0,
                rule: "must be >= 1",
            });
        }
        Ok(Self { ssm, params })
    }

    /// The separation-monitoring limits.
    pub fn ssm(&self) -> &SsmConfig {
        &self.ssm
    }

    /// The solver parameters.
    pub fn params(&self) -> &QpParams {
        &self.params
    }
}

/// One cycle's problem in normalised form (see the module docs). Built by [`Problem::build`];
/// shared by both solvers so they solve the same thing.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Problem {
    /// Reference after the TCP-cap scaling, rad/s.
    pub r: [f64; N_JOINTS],
    /// Box lower bound, rad/s.
    pub lo: [f64; N_JOINTS],
    /// Box upper bound, rad/s.
    pub hi: [f64; N_JOINTS],
    /// Unit-norm rows (dimensionless); only the first `m` are used.
    pub a: [[f64; N_JOINTS]; MAX_ROWS],
    /// Right-hand sides, rad/s (≥ 0).
    pub b: [f64; MAX_ROWS],
    /// Largest slack allowed per row, rad/s: `uᵢ = max(0, aᵢᵀ q̇_brake − bᵢ)`, so a row may be
    /// violated only down to what the braking fallback achieves.
    pub u: [f64; MAX_ROWS],
    /// Number of rows in use.
    pub m: usize,
    /// The braking fallback for this input, rad/s.
    pub brake: [f64; N_JOINTS],
}

fn finite3(v: &[f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn dot6(a: &[f64; N_JOINTS], b: &[f64; N_JOINTS]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `J q̇` for a 3×6 Jacobian, m/s.
fn jac_mul(j: &[[f64; N_JOINTS]; 3], qd: &[f64; N_JOINTS]) -> [f64; 3] {
    let mut v = [0.0; 3];
    for (vk, row) in v.iter_mut().zip(j) {
        *vk = dot6(row, qd);
    }
    v
}

/// `Jᵀ n`, m/rad.
fn jac_t_mul(j: &[[f64; N_JOINTS]; 3], n: &[f64; 3]) -> [f64; N_JOINTS] {
    let mut a = [0.0; N_JOINTS];
    for (row, nk) in j.iter().zip(n) {
        for (ai, jk) in a.iter_mut().zip(row) {
            *ai += jk * nk;
        }
    }
    a
}

fn norm3(v: &[f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Braking fallback: `q̇_prev` scaled toward 0 as fast as the acceleration limits allow, then
/// clamped into the velocity limits; zero if `q̇_prev`, the limits or `dt_s` are unusable.
pub fn braking_fallback(input: &QpInput, out: &mut [f64; N_JOINTS]) {
    let usable = input.dt_s.is_finite()
        && input.dt_s > 0.0
        && input.qd_prev.iter().all(|v| v.is_finite())
        && input
            .max_velocity
            .iter()
            .chain(&input.max_acceleration)
            .all(|v| v.is_finite() && *v >= 0.0);
    if !usable {
        *out = [0.0; N_JOINTS];
        return;
    }
    // Smallest common factor s ∈ [0, 1] with |q̇_prev,j| (1 − s) ≤ a_j dt for all j.
    let mut s: f64 = 0.0;
    for (p, a) in input.qd_prev.iter().zip(&input.max_acceleration) {
        let mag = p.abs();
        if mag > 0.0 {
            s = s.max(1.0 - a * input.dt_s / mag);
        }
    }
    let s = s.clamp(0.0, 1.0);
    for ((o, p), v) in out.iter_mut().zip(&input.qd_prev).zip(&input.max_velocity) {
        *o = (p * s).clamp(-v, *v);
    }
}

fn input_is_valid(input: &QpInput) -> bool {
    input.dt_s.is_finite()
        && input.dt_s > 0.0
        && input
            .qd_ref
            .iter()
            .chain(&input.qd_prev)
            .all(|v| v.is_finite())
        && input
            .max_velocity
            .iter()
            .chain(&input.max_acceleration)
            .all(|v| v.is_finite() && *v >= 0.0)
        && !input.tcp_speed_cap_m_s.is_nan()
        && input.tcp_speed_cap_m_s >= 0.0
        && input.control_points.iter().all(|c| {
            finite3(&c.position)
                && c.jacobian
                    .iter()
                    .all(|row| row.iter().all(|v| v.is_finite()))
        })
        && input.humans.iter().flatten().all(|h| finite3(&h.position))
}

impl Problem {
    /// Builds the normalised problem for `input`. Returns false (and leaves only `brake` set)
    /// if the input is invalid.
    pub fn build(&mut self, cfg: &QpConfig, input: &QpInput) -> bool {
        braking_fallback(input, &mut self.brake);
        self.m = 0;
        if !input_is_valid(input) {
            return false;
        }
        // Box.
        for j in 0..N_JOINTS {
            let (Some(v), Some(a), Some(p)) = (
                input.max_velocity.get(j),
                input.max_acceleration.get(j),
                input.qd_prev.get(j),
            ) else {
                continue;
            };
            let step = a * input.dt_s;
            let mut lo = (-v).max(p - step);
            let mut hi = v.min(p + step);
            if lo > hi {
                let pinned = p.clamp(-v, *v);
                lo = pinned;
                hi = pinned;
            }
            if let (Some(l), Some(h)) = (self.lo.get_mut(j), self.hi.get_mut(j)) {
                *l = lo;
                *h = hi;
            }
        }
        // Reference, scaled so the TCP speed is within the cap.
        self.r = input.qd_ref;
        let tcp = &input.control_points[0];
        let v_tcp = jac_mul(&tcp.jacobian, &self.r);
        let speed = norm3(&v_tcp);
        let cap = input.tcp_speed_cap_m_s;
        if speed > EPS_NORM {
            if speed > cap {
                let s = cap / speed;
                self.r.iter_mut().for_each(|x| *x *= s);
            }
            if cap.is_finite() {
                let u = [v_tcp[0] / speed, v_tcp[1] / speed, v_tcp[2] / speed];
                let a = jac_t_mul(&tcp.jacobian, &u);
                self.push_row(a, cap);
            }
        }
        // Separation rows.
        for cp in &input.control_points {
            for h in input.humans.iter().flatten() {
                let diff = [
                    h.position[0] - cp.position[0],
                    h.position[1] - cp.position[1],
                    h.position[2] - cp.position[2],
                ];
                let d = norm3(&diff);
                let limit = cfg.ssm.approach_speed_limit_m_s(h.kind, d);
                let n = if d > 1e-9 {
                    [diff[0] / d, diff[1] / d, diff[2] / d]
                } else {
                    let v = jac_mul(&cp.jacobian, &self.r);
                    let nv = norm3(&v);
                    if nv <= EPS_NORM {
                        continue;
                    }
                    [v[0] / nv, v[1] / nv, v[2] / nv]
                };
                let a = jac_t_mul(&cp.jacobian, &n);
                self.push_row(a, limit);
            }
        }
        true
    }

    /// Normalises and appends a row `aᵀ q̇ ≤ b` unless it cannot bind inside the box.
    fn push_row(&mut self, a: [f64; N_JOINTS], b: f64) {
        let norm = dot6(&a, &a).sqrt();
        if norm.is_nan() || norm <= EPS_NORM || !b.is_finite() {
            return;
        }
        let mut an = a;
        an.iter_mut().for_each(|x| *x /= norm);
        let bn = b / norm;
        // Largest value of aᵀx over the box.
        let max_over_box: f64 = an
            .iter()
            .zip(self.lo.iter().zip(&self.hi))
            .map(|(ai, (l, h))| if *ai >= 0.0 { ai * h } else { ai * l })
            .sum();
        if max_over_box <= bn {
            return;
        }
        let slack_max = (dot6(&an, &self.brake) - bn).max(0.0);
        if let (Some(row), Some(rhs), Some(u)) = (
            self.a.get_mut(self.m),
            self.b.get_mut(self.m),
            self.u.get_mut(self.m),
        ) {
            *row = an;
            *rhs = bn;
            *u = slack_max;
            self.m += 1;
        }
    }

    /// The rows in use.
    pub fn rows(&self) -> impl Iterator<Item = (&[f64; N_JOINTS], f64)> {
        self.a.iter().zip(self.b).take(self.m)
    }

    /// Decides whether a candidate `x` (already in the box) may be used: every row holds to
    /// `tol`, or each violated row approaches no faster than the braking fallback. Returns the
    /// largest row violation (rad/s, normalised) and whether `x` is acceptable.
    pub fn check(&self, x: &[f64; N_JOINTS], tol: f64) -> (f64, bool) {
        let mut worst: f64 = 0.0;
        let mut ok = true;
        for (a, b) in self.rows() {
            let ax = dot6(a, x);
            let viol = ax - b;
            worst = worst.max(viol);
            if viol > tol && ax > dot6(a, &self.brake).max(b) + tol {
                ok = false;
            }
        }
        (worst, ok)
    }

    fn clamp_to_box(&self, x: &mut [f64; N_JOINTS]) {
        for ((v, l), h) in x.iter_mut().zip(&self.lo).zip(&self.hi) {
            *v = v.max(*l).min(*h);
        }
    }
}

/// Closed-form projection onto a box and one half-space:
/// `out = argmin ½‖x − c‖² + λ_max · max(0, aᵀx − b)` over `lo ≤ x ≤ hi`, i.e.
/// `out = clip(c − λ a, lo, hi)` with the multiplier `λ ∈ [0, λ_max]` returned. `λ` is the root of
/// the nonincreasing piecewise-linear `φ(t) = aᵀ clip(c − t a, lo, hi) − b`, found exactly by
/// walking its breakpoints in order (≤ 12, sorted in place). Units: any consistent velocity unit.
/// With `λ_max = ∞` this is the exact projection when the set is non-empty.
pub fn project_box_halfspace(
    c: &[f64; N_JOINTS],
    lo: &[f64; N_JOINTS],
    hi: &[f64; N_JOINTS],
    a: &[f64; N_JOINTS],
    b: f64,
    lambda_max: f64,
    out: &mut [f64; N_JOINTS],
) -> f64 {
    let phi = |t: f64| -> f64 {
        let mut s = -b;
        for j in 0..N_JOINTS {
            if let (Some(cj), Some(aj), Some(l), Some(h)) =
                (c.get(j), a.get(j), lo.get(j), hi.get(j))
            {
                s += aj * (cj - t * aj).max(*l).min(*h);
            }
        }
        s
    };
    let mut t = 0.0;
    let mut phi_prev = phi(0.0);
    if phi_prev > 0.0 {
        let mut bp = [0.0f64; 2 * N_JOINTS];
        let mut nbp = 0usize;
        for j in 0..N_JOINTS {
            let (Some(cj), Some(aj), Some(l), Some(h)) = (c.get(j), a.get(j), lo.get(j), hi.get(j))
            else {
                continue;
            };
            if aj.abs() > 0.0 {
                for bound in [l, h] {
                    let tb = (cj - bound) / aj;
                    if tb > 0.0
                        && tb < lambda_max
                        && let Some(slot) = bp.get_mut(nbp)
                    {
                        *slot = tb;
                        nbp += 1;
                    }
                }
            }
        }
        let bp = bp.get_mut(..nbp).unwrap_or(&mut []);
        bp.sort_unstable_by(f64::total_cmp);
        let mut t_prev = 0.0;
        let mut found = false;
        for &tk in bp.iter().chain(std::iter::once(&lambda_max)) {
            let phi_k = if tk.is_finite() {
                phi(tk)
            } else {
                f64::NEG_INFINITY
            };
            if phi_k <= 0.0 {
                t = if tk.is_finite() && phi_prev - phi_k > 0.0 {
                    t_prev + phi_prev * (tk - t_prev) / (phi_prev - phi_k)
                } else if tk.is_finite() {
                    tk
                } else {
                    // λ_max = ∞ and φ > 0 after the last breakpoint: every coordinate that moves
                    // with t is at a bound, so φ is constant; the last breakpoint is the corner
                    // of least violation.
                    t_prev
                };
                found = true;
                break;
            }
            t_prev = tk;
            phi_prev = phi_k;
        }
        if !found {
            t = lambda_max;
        }
    }
    for j in 0..N_JOINTS {
        if let (Some(o), Some(cj), Some(aj), Some(l), Some(h)) =
            (out.get_mut(j), c.get(j), a.get(j), lo.get(j), hi.get(j))
        {
            *o = (cj - t * aj).max(*l).min(*h);
        }
    }
    t
}

/// Diagnostics of the last [`SpeedScaler::solve`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct QpReport {
    /// Rows (separation pairs + TCP cap) that could bind this cycle.
    pub rows: usize,
    /// Coordinate-ascent sweeps used (0: the box projection was already feasible).
    pub sweeps: u32,
    /// Largest row violation of the output, on the normalised rows, rad/s (≤ 0 when all hold).
    pub max_violation_rad_s: f64,
}

/// The 500 Hz speed scaler: allocation-free after [`SpeedScaler::new`].
#[derive(Debug, Clone)]
pub struct SpeedScaler {
    cfg: QpConfig,
    problem: Problem,
    lambda: [f64; MAX_ROWS],
    report: QpReport,
}

impl SpeedScaler {
    /// Builds the scaler (all memory is inline; nothing is allocated later).
    pub fn new(cfg: QpConfig) -> Result<Self> {
        Ok(Self {
            cfg,
            problem: Problem::default(),
            lambda: [0.0; MAX_ROWS],
            report: QpReport::default(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &QpConfig {
        &self.cfg
    }

    /// Diagnostics of the last `solve`.
    pub fn report(&self) -> &QpReport {
        &self.report
    }

    /// The problem posed in the last `solve` (for logging and cross-checks).
    pub fn problem(&self) -> &Problem {
        &self.problem
    }

    /// One cycle: writes the scaled joint velocity (rad/s) to `out`. Allocates nothing, never
    /// panics; see [`QpStatus`] for what each outcome means for `out`.
    pub fn solve(&mut self, input: &QpInput, out: &mut [f64; N_JOINTS]) -> QpStatus {
        self.report = QpReport::default();
        let p = &mut self.problem;
        if !p.build(&self.cfg, input) {
            *out = p.brake;
            return QpStatus::InvalidInput;
        }
        self.report.rows = p.m;
        let tol = self.cfg.params.tolerance_rad_s;
        let rho = self.cfg.params.slack_penalty_rad_s;

        // 1. Box projection.
        let mut x = p.r;
        p.clamp_to_box(&mut x);
        let (worst, _) = p.check(&x, tol);
        if worst <= tol {
            *out = x;
            self.report.max_violation_rad_s = worst;
            return QpStatus::Solved;
        }

        // 2. Dual coordinate ascent on λ ∈ [0, ρ]^m; c = r − Aᵀλ, x(λ) = clip(c).
        self.lambda = [0.0; MAX_ROWS];
        let mut c = p.r;
        let mut converged = false;
        let mut sweeps = 0;
        let mut tmp = [0.0; N_JOINTS];
        while sweeps < self.cfg.params.max_sweeps {
            sweeps += 1;
            for (i, (a, b)) in p.a.iter().zip(p.b).take(p.m).enumerate() {
                let Some(li) = self.lambda.get_mut(i) else {
                    continue;
                };
                for (cj, aj) in c.iter_mut().zip(a) {
                    *cj += *li * aj;
                }
                let u = p.u.get(i).copied().unwrap_or(0.0);
                let mut t = project_box_halfspace(&c, &p.lo, &p.hi, a, b, rho, &mut tmp);
                if t >= rho && dot6(a, &tmp) > b + u {
                    // Slack exhausted: the row is hard at b + u (never worse than braking).
                    t = project_box_halfspace(&c, &p.lo, &p.hi, a, b + u, f64::INFINITY, &mut tmp);
                }
                *li = t;
                for (cj, aj) in c.iter_mut().zip(a) {
                    *cj -= t * aj;
                }
            }
            // KKT check on x(λ).
            x = c;
            p.clamp_to_box(&mut x);
            converged = p
                .rows()
                .zip(self.lambda.iter().zip(&p.u))
                .all(|((a, b), (l, u))| {
                    let v = dot6(a, &x) - b;
                    if *l <= 0.0 {
                        v <= tol
                    } else if *l < rho {
                        v.abs() <= tol
                    } else if *l == rho {
                        v >= -tol && v <= u + tol
                    } else {
                        (v - u).abs() <= tol
                    }
                });
            if converged {
                break;
            }
        }
        self.report.sweeps = sweeps;
        let (worst, acceptable) = p.check(&x, tol);
        self.report.max_violation_rad_s = worst;
        if !x.iter().all(|v| v.is_finite()) || !acceptable {
            *out = p.brake;
            return QpStatus::Infeasible;
        }
        *out = x;
        if !converged {
            QpStatus::TimeLimit
        } else if worst > tol {
            QpStatus::SolvedWithSlack
        } else {
            QpStatus::Solved
        }
    }
}

/// The same problem posed to clarabel (interior point), for cross-checks and benchmarks.
/// Built once; each cycle updates `q`, `b` and `A` in place (presolve, equilibration and zero
/// dropping off, so the sparsity is fixed). Not for the 500 Hz cycle: clarabel 0.11.1
/// allocates in every `solve` (see the module docs).
pub struct ClarabelSpeedScaler {
    cfg: QpConfig,
    problem: Problem,
    solver: clarabel::solver::DefaultSolver<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
    a_vals: Vec<f64>,
    report: QpReport,
}

impl std::fmt::Debug for ClarabelSpeedScaler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClarabelSpeedScaler")
            .field("cfg", &self.cfg)
            .field("report", &self.report)
            .finish_non_exhaustive()
    }
}

const M: usize = MAX_ROWS;
const N_VARS: usize = N_JOINTS + M;
const N_CONS: usize = 3 * M + 2 * N_JOINTS;

impl ClarabelSpeedScaler {
    /// Builds the clarabel solver for the fixed sparsity: variables `[q̇ (6); s (10)]`, rows
    /// `aᵢᵀq̇ − sᵢ ≤ bᵢ`, `−sᵢ ≤ 0`, `sᵢ ≤ uᵢ`, `q̇ ≤ hi`, `−q̇ ≤ −lo`, all in one non-negative
    /// cone.
    pub fn new(cfg: QpConfig) -> Result<Self> {
        use clarabel::algebra::CscMatrix;
        use clarabel::solver::{DefaultSettingsBuilder, DefaultSolver, NonnegativeConeT};
        let setup = |reason: String| AdaptError::QpSetup { reason };
        // P = diag(1 for q̇, 0 for s): upper triangle, slack columns empty.
        let mut colptr = Vec::with_capacity(N_VARS + 1);
        let mut rowval = Vec::new();
        for j in 0..N_VARS {
            colptr.push(rowval.len());
            if j < N_JOINTS {
                rowval.push(j);
            }
        }
        colptr.push(rowval.len());
        let p_mat = CscMatrix::new(N_VARS, N_VARS, colptr, rowval, vec![1.0; N_JOINTS]);
        // A.
        let mut colptr = Vec::with_capacity(N_VARS + 1);
        let mut rowval = Vec::new();
        let mut nzval = Vec::new();
        for j in 0..N_JOINTS {
            colptr.push(rowval.len());
            for i in 0..M {
                rowval.push(i);
                nzval.push(0.0);
            }
            rowval.push(3 * M + j);
            nzval.push(1.0);
            rowval.push(3 * M + N_JOINTS + j);
            nzval.push(-1.0);
        }
        for i in 0..M {
            colptr.push(rowval.len());
            rowval.push(i);
            nzval.push(-1.0);
            rowval.push(M + i);
            nzval.push(-1.0);
            rowval.push(2 * M + i);
            nzval.push(1.0);
        }
        colptr.push(rowval.len());
        let a_vals = nzval.clone();
        let a_mat = CscMatrix::new(N_CONS, N_VARS, colptr, rowval, nzval);
        let mut q = vec![0.0; N_VARS];
        for s in q.iter_mut().skip(N_JOINTS) {
            *s = cfg.params.slack_penalty_rad_s;
        }
        let mut b = vec![1.0; N_CONS];
        for v in b.iter_mut().skip(M).take(2 * M) {
            *v = 0.0;
        }
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .equilibrate_enable(false)
            .input_sparse_dropzeros(false)
            .max_iter(100)
            .tol_gap_abs(1e-10)
            .tol_gap_rel(1e-10)
            .tol_feas(1e-10)
            .build()
            .map_err(|e| setup(e.to_string()))?;
        let cones = [NonnegativeConeT(N_CONS)];
        let solver = DefaultSolver::new(&p_mat, &q, &a_mat, &b, &cones, settings)
            .map_err(|e| setup(e.to_string()))?;
        Ok(Self {
            cfg,
            problem: Problem::default(),
            solver,
            q,
            b,
            a_vals,
            report: QpReport::default(),
        })
    }

    /// Diagnostics of the last `solve` (`sweeps` = interior-point iterations).
    pub fn report(&self) -> &QpReport {
        &self.report
    }

    /// One cycle with clarabel; same contract and statuses as [`SpeedScaler::solve`]
    /// ([`QpStatus::TimeLimit`] when clarabel stops on its iteration or time limit).
    pub fn solve(&mut self, input: &QpInput, out: &mut [f64; N_JOINTS]) -> QpStatus {
        use clarabel::solver::{IPSolver, SolverStatus};
        self.report = QpReport::default();
        let p = &mut self.problem;
        if !p.build(&self.cfg, input) {
            *out = p.brake;
            return QpStatus::InvalidInput;
        }
        self.report.rows = p.m;
        let tol = self.cfg.params.tolerance_rad_s;
        // q = [−r; ρ].
        for (qj, rj) in self.q.iter_mut().zip(&p.r) {
            *qj = -rj;
        }
        // b and the row values; unused rows are 0 ≤ 1.
        for i in 0..M {
            let (row, rhs, u) = match (p.a.get(i), p.b.get(i), p.u.get(i)) {
                (Some(row), Some(rhs), Some(u)) if i < p.m => (*row, *rhs, *u),
                _ => ([0.0; N_JOINTS], 1.0, 0.0),
            };
            if let Some(v) = self.b.get_mut(i) {
                *v = rhs;
            }
            if let Some(v) = self.b.get_mut(2 * M + i) {
                *v = u;
            }
            for (j, aij) in row.iter().enumerate() {
                if let Some(v) = self.a_vals.get_mut(j * (M + 2) + i) {
                    *v = *aij;
                }
            }
        }
        for (j, (h, l)) in p.hi.iter().zip(&p.lo).enumerate() {
            if let Some(v) = self.b.get_mut(3 * M + j) {
                *v = *h;
            }
            if let Some(v) = self.b.get_mut(3 * M + N_JOINTS + j) {
                *v = -l;
            }
        }
        let updated = self
            .solver
            .update_q(&self.q)
            .and_then(|()| self.solver.update_b(&self.b))
            .and_then(|()| self.solver.update_A(&self.a_vals));
        if updated.is_err() {
            *out = p.brake;
            return QpStatus::Infeasible;
        }
        self.solver.solve();
        let sol = &self.solver.solution;
        self.report.sweeps = sol.iterations;
        let status = sol.status;
        let mut x = [0.0; N_JOINTS];
        for (xj, sj) in x.iter_mut().zip(&sol.x) {
            *xj = *sj;
        }
        p.clamp_to_box(&mut x);
        let (worst, acceptable) = p.check(&x, 1e-6_f64.max(tol));
        self.report.max_violation_rad_s = worst;
        let usable = matches!(
            status,
            SolverStatus::Solved
                | SolverStatus::AlmostSolved
                | SolverStatus::MaxIterations
                | SolverStatus::MaxTime
        );
        if !usable || !x.iter().all(|v| v.is_finite()) || !acceptable {
            *out = p.brake;
            return QpStatus::Infeasible;
        }
        *out = x;
        match status {
            SolverStatus::MaxIterations | SolverStatus::MaxTime => QpStatus::TimeLimit,
            _ if worst > 1e-6_f64.max(tol) => QpStatus::SolvedWithSlack,
            _ => QpStatus::Solved,
        }
    }
}
