//! **SIMULATED OPERATOR** — a seeded stochastic model of a human doing the paper's gearbox
//! assembly (its §"Task design", Table "Collaborative assembly tasks and score-derived difficulty
//! profiles"). Nothing here is measured human data: every cue it emits is simulation, and the
//! logs say so (`source = "simulated_operator"`).
//!
//! # Task (from the paper)
//! - **L1**: the robot delivers one component (one of C1–C4);
//! - **L2**: two components and the screwdriver C5;
//! - **L3**: two components and the fastening module C6 (screwdriver and screws).
//!
//! The paper gives the deliveries but **no** dwell times, transition rates or hesitation
//! statistics. The cue noise, the cue confidences, the torso height and the hand speed in
//! [`COMMON`] are **fitted** to measurements (the perception pipeline's own jitter on the
//! bundled photos, and the bundled real KTH handover: `docs/calibration/operator_fit.md`, each
//! field's doc names its source). Every other number in [`LevelParams::for_level`] and
//! [`COMMON`] is **our assumption**, chosen so that (a) a trial lasts 1.5–3 simulated minutes (the assessor needs
//! its 60 s baseline before a dominant indicator can appear), (b) complexity grows L1 → L3 as
//! the table's difficulty profiles say (more robot resources to coordinate, more instruction
//! checking and searching), and (c) the magnitudes are plausible for seated bench assembly.
//!
//! # Model
//! The operator works through `n + 1` assembly segments around `n` handovers. In a segment it
//! dwells in the assembly area, and leaves it at Poisson rates for the storage area (tool
//! identification) and the instruction area, with log-normal dwell times. While the robot moves
//! or presents, it glances at the collaboration area (monitoring). When a segment's work is done
//! it needs the next part: it looks at the collaboration area and, once the robot presents,
//! reaches for the TCP (its right hand moves at a bounded speed towards the presented TCP);
//! the controller detects the grasp (hand within r_grasp for t_grasp) and releases. Operator idle
//! time (waiting for a part) and robot waits (presenting before the operator reaches) emerge from
//! this closed loop.
//!
//! **Hesitation**: during a collaboration period (robot approaching or presenting) with the
//! handover incomplete, hesitation episodes (the hand freezes, the head stays on the robot)
//! start at a Poisson rate `base × (1 + k_speed·v/v_ref + k_acc·a/a_ref)` (v, a: the robot TCP's
//! speed and peak acceleration over the last cue interval) and with an extra probability when
//! the robot starts presenting while the operator's attention is elsewhere ("surprise"). Their
//! durations are log-normal, lengthened by the same stress factor. These effect sizes are the
//! trial config's `[operator.response]` ([`OperatorResponse`], all assumptions).
//!
//! **Cues**: head (position and facing), torso and both hands in the workspace frame [m], at the
//! cue rate, with Gaussian noise and independent and burst dropouts ([`COMMON`]).
//!
//! Deterministic for a seed: [`policies::SplitMix64`] drives every draw, and the operator steps
//! only on the injected trial time.

use adapt::task::Phase;
use assess::{AreaRole, BodyCue, CueFrame, HandCue, HeadCue, Vec3, Workspace};
use policies::SplitMix64;

use super::config::OperatorResponse;
use super::events::TrialEvent;

/// Experimental condition (task complexity level) of the paper.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Level {
    /// One delivered component.
    L1,
    /// Two components and a screwdriver.
    L2,
    /// Two components and a fastening module (screwdriver and screws).
    L3,
}

impl Level {
    /// `L1`, `L2` or `L3`.
    pub fn as_str(self) -> &'static str {
        match self {
            Level::L1 => "L1",
            Level::L2 => "L2",
            Level::L3 => "L3",
        }
    }
}

impl std::str::FromStr for Level {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Level> {
        match s {
            "L1" | "l1" => Ok(Level::L1),
            "L2" | "l2" => Ok(Level::L2),
            "L3" | "l3" => Ok(Level::L3),
            _ => Err(crate::Error::usage(
                "--condition",
                format!("unknown condition {s:?}: expected L1, L2 or L3"),
            )),
        }
    }
}

/// Per-level parameters of the simulated operator. All numbers are **our assumptions** (the
/// paper gives none); the rationale is on each field.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LevelParams {
    /// What the robot delivers, in order (from the paper's table).
    pub(crate) deliveries: &'static [&'static str],
    /// Nominal assembly work of each segment (before handover 1, …, after the last) [s of
    /// assembly dwell]. Assumption: 25–40 s per gearbox sub-assembly step; the last segment
    /// (fastening) is longer at L2/L3.
    pub(crate) work_s: &'static [f64],
    /// Log-normal spread of each segment's actual work [-, σ of ln]. Assumption: 0.2 (±20 %).
    pub(crate) work_sigma: f64,
    /// Rate of trips to the storage area (tool identification) while assembling [1/s].
    /// Assumption: one every ~30 s (L1) to ~17 s (L3): more parts and tools to find.
    pub(crate) storage_rate_per_s: f64,
    /// Median storage dwell [s]. Assumption: 2–3.5 s to find a part or tool.
    pub(crate) storage_dwell_s: f64,
    /// Rate of instruction checks while assembling [1/s]. Assumption: one every ~33 s (L1) to
    /// ~14 s (L3): more sequencing demand.
    pub(crate) instruction_rate_per_s: f64,
    /// Median instruction dwell [s]. Assumption: 2–4 s of reading.
    pub(crate) instruction_dwell_s: f64,
    /// Log-normal spread of the dwell times above [-]. Assumption: 0.4.
    pub(crate) dwell_sigma: f64,
    /// Rate of monitoring glances at the robot while it moves or presents and the operator is
    /// still assembling [1/s]. Assumption: 0.10 (L1) to 0.25 (L3): "robot monitoring" demand.
    pub(crate) monitor_rate_per_s: f64,
    /// Median monitoring glance [s]. Assumption: 1.0 s.
    pub(crate) monitor_dwell_s: f64,
    /// Base hesitation rate during a collaboration period [1/s]. Assumption: 0.04 (L1) to 0.08
    /// (L3).
    pub(crate) hesitation_rate_per_s: f64,
    /// Median hesitation duration at no stress [s]. Assumption: 1.2–1.8 s (OHD needs sustained
    /// low motion, t_min, to count one).
    pub(crate) hesitation_s: f64,
}

impl LevelParams {
    /// The parameters of a level (see the field docs for the sources: all assumptions).
    pub(crate) fn for_level(level: Level) -> LevelParams {
        match level {
            Level::L1 => LevelParams {
                deliveries: &["component C1-C4"],
                work_s: &[45.0, 40.0],
                work_sigma: 0.2,
                storage_rate_per_s: 0.033,
                storage_dwell_s: 2.0,
                instruction_rate_per_s: 0.03,
                instruction_dwell_s: 2.0,
                dwell_sigma: 0.4,
                monitor_rate_per_s: 0.10,
                monitor_dwell_s: 1.0,
                hesitation_rate_per_s: 0.04,
                hesitation_s: 1.2,
            },
            Level::L2 => LevelParams {
                deliveries: &["component C1-C4", "component C1-C4", "screwdriver C5"],
                work_s: &[35.0, 28.0, 28.0, 35.0],
                work_sigma: 0.2,
                storage_rate_per_s: 0.045,
                storage_dwell_s: 2.5,
                instruction_rate_per_s: 0.05,
                instruction_dwell_s: 3.0,
                dwell_sigma: 0.4,
                monitor_rate_per_s: 0.18,
                monitor_dwell_s: 1.0,
                hesitation_rate_per_s: 0.06,
                hesitation_s: 1.5,
            },
            Level::L3 => LevelParams {
                deliveries: &["component C1-C4", "component C1-C4", "fastening module C6"],
                work_s: &[35.0, 30.0, 30.0, 40.0],
                work_sigma: 0.2,
                storage_rate_per_s: 0.06,
                storage_dwell_s: 3.5,
                instruction_rate_per_s: 0.07,
                instruction_dwell_s: 4.0,
                dwell_sigma: 0.4,
                monitor_rate_per_s: 0.25,
                monitor_dwell_s: 1.0,
                hesitation_rate_per_s: 0.08,
                hesitation_s: 1.8,
            },
        }
    }

    /// Number of handovers.
    pub(crate) fn handovers(&self) -> usize {
        self.deliveries.len()
    }

    /// Expected wall-time share of assembly work in a segment: 1 + expected excursion time
    /// per second of work [-] (used for the robot's nominal schedule).
    pub(crate) fn overhead_factor(&self) -> f64 {
        let m = (self.dwell_sigma * self.dwell_sigma / 2.0).exp();
        1.0 + self.storage_rate_per_s * self.storage_dwell_s * m
            + self.instruction_rate_per_s * self.instruction_dwell_s * m
    }
}

/// Level-independent parameters (all **our assumptions**).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct CommonParams {
    /// Head position when seated [m] (workspace frame: origin on the floor below the seat).
    pub(crate) head_m: [f64; 3],
    /// Torso position [m]: the shoulder midpoint, which is what the camera front-end and the
    /// KTH reader report as the body cue. Fitted (z): 0.154 m below the head in the KTH
    /// recording (`docs/calibration/operator_fit.md`, `kth_kinematics.csv`
    /// `taker_body,all,head_minus_shoulder_z_median`); x, y: assumption.
    pub(crate) torso_m: [f64; 3],
    /// Reach origin [m]: the right shoulder with the trunk leaning forward and turned towards
    /// the handover area (assumption).
    pub(crate) shoulder_m: [f64; 3],
    /// Longest reach from the reach origin [m] (a seated adult's arm ~0.75 m plus trunk lean;
    /// assumption; a further TCP is approached to this distance only).
    pub(crate) reach_m: f64,
    /// Hand speed moving between areas and reaching [m/s]. Fitted: 0.42 m/s covers the KTH
    /// taker's reach (0.422 m) in its measured duration (1.017 s; `kth_kinematics.csv`
    /// `taker_right,reach,net_over_duration`); the model moves at a constant speed, the person
    /// peaked at 0.75 m/s (`operator_fit.md`).
    pub(crate) hand_speed_m_s: f64,
    /// Gaze point speed (head turn) [m/s] at ~1 m: ~0.3 s per area change.
    pub(crate) gaze_speed_m_s: f64,
    /// Working-motion radius of the hand at the fixture [m] and its frequency [Hz].
    /// Assumption, constrained by the assessment: 0.03 m at 1 Hz filters to v_h ≈ 0.13 m/s,
    /// above v_max = 0.10 m/s, so an assembling hand is never low motion (0.02 m gave 0.088
    /// m/s, below it); its raw 0.2 m/s lies between KTH's slow manipulation and its reach
    /// (`operator_fit.md`).
    pub(crate) work_motion_m: f64,
    /// See `work_motion_m` [Hz].
    pub(crate) work_motion_hz: f64,
    /// Motion radius of the hand holding the presented part at the handover point [m], in
    /// the working motion's shape and frequency. Fitted to the KTH taker's hold (grip closing
    /// and the start of the pull; `kth_kinematics.csv` `taker_right,hold,mean_speed` 0.112
    /// m/s, v_h median 0.077 m/s): 0.0175 m at 1 Hz has a raw mean of 0.117 m/s, and the
    /// assessment's filter gives it v_h ≈ 0.077 m/s
    /// (`the_hold_motion_filters_to_the_measured_kth_hold_speed`). A real hold is not frozen.
    pub(crate) hold_motion_m: f64,
    /// Position noise σ of hands [m] and head/torso [m], independent per frame and axis.
    /// Fitted (`operator_fit.md`): hands 1.5 mm, the perception pipeline's worst still-hand
    /// jitter with depth (0.84 mm, `cue_noise.csv`) plus tremor, which keeps a frozen hand's
    /// filtered speed below v_min = 0.03 m/s on 96.5 % of 0.3 s windows (5 mm never did);
    /// head/torso 0.5 mm, the measured frame-to-frame jitter (the measured slow wander, lag-1
    /// 0.6–0.95, is not modelled: the noise is iid).
    pub(crate) hand_noise_m: f64,
    /// See `hand_noise_m` [m].
    pub(crate) body_noise_m: f64,
    /// Facing-direction noise σ per axis of the unit vector [rad], iid. Fitted: 1 mrad, the
    /// measured frame-to-frame jitter of the head and torso facing (0.2–1.5 mrad,
    /// `cue_noise.csv`; `operator_fit.md`). Real head turns are the gaze process, not noise.
    pub(crate) facing_noise_rad: f64,
    /// Independent per-cue dropout probability per frame [-].
    pub(crate) dropout_p: f64,
    /// Probability per frame that a hand-occlusion burst starts [-], and its length [s].
    pub(crate) burst_p: f64,
    /// See `burst_p` [s].
    pub(crate) burst_s: f64,
}

/// The common parameters (all assumptions; see the field docs).
pub(crate) const COMMON: CommonParams = CommonParams {
    head_m: [0.0, 0.0, 1.2],
    torso_m: [0.0, 0.0, 1.05],
    shoulder_m: [0.2, 0.0, 1.05],
    reach_m: 1.0,
    hand_speed_m_s: 0.42,
    gaze_speed_m_s: 3.0,
    work_motion_m: 0.03,
    work_motion_hz: 1.0,
    hold_motion_m: 0.0175,
    hand_noise_m: 0.0015,
    body_noise_m: 0.0005,
    facing_noise_rad: 0.001,
    dropout_p: 0.02,
    burst_p: 0.004,
    burst_s: 0.5,
};

/// The working motion's shape at time `t` [s] and frequency `hz` [Hz], for a radius of 1 m: a
/// horizontal circle with a vertical wobble at twice the frequency (times the radius [m]).
fn work_motion(t: f64, hz: f64) -> Vec3 {
    let w = std::f64::consts::TAU * hz * t;
    Vec3::new(w.cos(), w.sin(), 0.3 * (2.0 * w).sin())
}

/// What the operator sees of the robot, in the workspace frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct RobotView {
    /// Handover task phase.
    pub(crate) phase: Phase,
    /// TCP position [m], workspace frame.
    pub(crate) tcp_m: [f64; 3],
    /// TCP speed [m/s].
    pub(crate) tcp_speed_m_s: f64,
    /// Peak TCP acceleration since the last cue frame [m/s²].
    pub(crate) tcp_peak_acc_m_s2: f64,
}

/// Small wrapper over SplitMix64 with the draws the model needs.
#[derive(Debug, Clone)]
struct Rng(SplitMix64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        (self.0.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
    fn lognormal(&mut self, median: f64, sigma: f64) -> f64 {
        median * (sigma * self.normal()).exp()
    }
    fn chance(&mut self, p: f64) -> bool {
        self.uniform() < p
    }
}

/// What the operator is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    /// Assembling (segment work counts down while here).
    Working,
    /// Away from assembly until a time [s], attending an area.
    Excursion { role: AreaRole, until: f64 },
    /// Needs the next part; waits for the robot to present.
    NeedsPart,
    /// Reaching for / holding the presented part.
    Reaching,
    /// All work done.
    Done,
}

/// The simulated operator (see the module docs). **Simulation, not measured data.**
#[derive(Debug)]
pub(crate) struct SimulatedOperator {
    params: LevelParams,
    response: OperatorResponse,
    rng: Rng,
    centres: [Vec3; 4],
    assembly_point: Vec3,
    mode: Mode,
    segment: usize,
    work_left_s: f64,
    handover: u32,
    hesitation_until: Option<f64>,
    last_phase: Phase,
    gaze: Vec3,
    hand: Vec3,
    left_hand: Vec3,
    burst_until: f64,
    last_t: Option<f64>,
    events: Vec<TrialEvent>,
}

impl SimulatedOperator {
    /// A new operator at time 0 for `level`, drawing from `seed`, responding to the robot as
    /// `response` says. The workspace must have all four roles.
    pub(crate) fn new(
        level: Level,
        workspace: &Workspace,
        seed: u64,
        response: OperatorResponse,
    ) -> crate::Result<Self> {
        let params = LevelParams::for_level(level);
        let mut centres = [Vec3::zeros(); 4];
        for (i, role) in AreaRole::ALL.iter().enumerate() {
            let id = workspace.by_role(*role).ok_or_else(|| {
                crate::Error::data(
                    "the workspace",
                    format!("the simulated operator needs an area with role {role:?}"),
                )
            })?;
            centres[i] = workspace.area(id).representative_centre;
        }
        let mut rng = Rng(SplitMix64::new(seed ^ 0x5EED_0F0B_E2A7_u64));
        let work = rng.lognormal(params.work_s[0], params.work_sigma);
        let assembly_point = centres[0];
        Ok(SimulatedOperator {
            rng,
            centres,
            assembly_point,
            mode: Mode::Working,
            segment: 0,
            work_left_s: work,
            handover: 0,
            hesitation_until: None,
            last_phase: Phase::Idle,
            gaze: assembly_point,
            hand: assembly_point,
            left_hand: assembly_point + Vec3::new(-0.1, 0.15, 0.0),
            burst_until: f64::NEG_INFINITY,
            last_t: None,
            params,
            response,
            events: Vec::with_capacity(8),
        })
    }

    /// The level's parameters.
    pub(crate) fn params(&self) -> &LevelParams {
        &self.params
    }

    /// All segments done.
    pub(crate) fn finished(&self) -> bool {
        self.mode == Mode::Done
    }

    /// The operator is hesitating (ground truth of the simulation).
    #[allow(dead_code)]
    pub(crate) fn hesitating(&self) -> bool {
        self.hesitation_until.is_some()
    }

    /// The handover the operator is waiting for or reaching for (1-based), if any.
    #[allow(dead_code)]
    pub(crate) fn awaiting(&self) -> Option<u32> {
        matches!(self.mode, Mode::NeedsPart | Mode::Reaching).then_some(self.handover + 1)
    }

    /// Events of the last [`SimulatedOperator::step`] or
    /// [`SimulatedOperator::release_confirmed`].
    pub(crate) fn events(&self) -> &[TrialEvent] {
        &self.events
    }

    fn centre(&self, role: AreaRole) -> Vec3 {
        let i = AreaRole::ALL.iter().position(|r| *r == role).unwrap_or(0);
        self.centres[i]
    }

    /// The controller confirmed the release: the operator holds the part and goes back to
    /// assembling. Emits `Grasped` and `OperatorIdle { idle: false }`.
    pub(crate) fn release_confirmed(&mut self) {
        self.events.clear();
        if !matches!(self.mode, Mode::Reaching | Mode::NeedsPart) {
            return;
        }
        self.handover += 1;
        self.events.push(TrialEvent::Grasped {
            handover: self.handover,
        });
        self.events.push(TrialEvent::OperatorIdle { idle: false });
        self.end_hesitation();
        self.segment += 1;
        let nominal = self.params.work_s.get(self.segment).copied().unwrap_or(0.0);
        self.work_left_s = self.rng.lognormal(nominal, self.params.work_sigma);
        self.mode = Mode::Working;
    }

    fn end_hesitation(&mut self) {
        if self.hesitation_until.take().is_some() {
            self.events.push(TrialEvent::Hesitation { active: false });
        }
    }

    fn start_hesitation(&mut self, t: f64, stress: f64) {
        if self.hesitation_until.is_none() {
            let k = self.response.k_duration;
            let d = self
                .rng
                .lognormal(self.params.hesitation_s * (1.0 + k * stress), 0.3);
            self.hesitation_until = Some(t + d);
            self.events.push(TrialEvent::Hesitation { active: true });
        }
    }

    /// Advance to time `t` [s] seeing `robot`, and write this frame's cues into `frame`
    /// (workspace frame, metres; `frame.t = t`; the robot context is left to the caller).
    pub(crate) fn step(&mut self, t: f64, robot: &RobotView, frame: &mut CueFrame) {
        self.events.clear();
        let dt = self.last_t.map_or(0.0, |l| (t - l).max(0.0));
        self.last_t = Some(t);
        let p = self.params.clone();
        let c = COMMON;
        let r = self.response;

        // Hesitation: end, or start during a collaboration period with the handover pending.
        if self.hesitation_until.is_some_and(|u| t >= u) {
            self.end_hesitation();
        }
        let collaborating = robot.phase.is_collaborating();
        let stress = r.k_speed * robot.tcp_speed_m_s / r.ref_speed_m_s
            + r.k_acc * robot.tcp_peak_acc_m_s2 / r.ref_acc_m_s2;
        let presenting_now = robot.phase == Phase::Present && self.last_phase != Phase::Present;
        if presenting_now && self.mode != Mode::Done {
            let attention_elsewhere = !matches!(self.mode, Mode::NeedsPart | Mode::Reaching);
            if attention_elsewhere && self.rng.chance(r.surprise_p) {
                self.start_hesitation(t, stress + r.surprise_stress);
            }
        }
        self.last_phase = robot.phase;
        if collaborating
            && matches!(self.mode, Mode::NeedsPart | Mode::Reaching)
            && self
                .rng
                .chance(p.hesitation_rate_per_s * (1.0 + stress) * dt)
        {
            self.start_hesitation(t, stress);
        }
        let hesitating = self.hesitation_until.is_some();

        // Activity.
        match self.mode {
            Mode::Working => {
                if !hesitating {
                    self.work_left_s -= dt;
                }
                let robot_busy = collaborating;
                if self.work_left_s <= 0.0 {
                    if self.segment < p.handovers() {
                        self.mode = Mode::NeedsPart;
                        self.events.push(TrialEvent::OperatorNeedsPart {
                            handover: self.handover + 1,
                        });
                        self.events.push(TrialEvent::OperatorIdle { idle: true });
                    } else {
                        self.mode = Mode::Done;
                    }
                } else if self.rng.chance(p.storage_rate_per_s * dt) {
                    let until = t + self.rng.lognormal(p.storage_dwell_s, p.dwell_sigma);
                    self.mode = Mode::Excursion {
                        role: AreaRole::ToolIdentification,
                        until,
                    };
                } else if self.rng.chance(p.instruction_rate_per_s * dt) {
                    let until = t + self.rng.lognormal(p.instruction_dwell_s, p.dwell_sigma);
                    self.mode = Mode::Excursion {
                        role: AreaRole::Instruction,
                        until,
                    };
                } else if robot_busy && self.rng.chance(p.monitor_rate_per_s * dt) {
                    let until = t + self.rng.lognormal(p.monitor_dwell_s, p.dwell_sigma);
                    self.mode = Mode::Excursion {
                        role: AreaRole::Collaboration,
                        until,
                    };
                }
            }
            Mode::Excursion { until, .. } => {
                if t >= until {
                    self.mode = Mode::Working;
                }
            }
            Mode::NeedsPart => {
                if robot.phase == Phase::Present && !hesitating {
                    self.mode = Mode::Reaching;
                }
            }
            Mode::Reaching => {
                if !matches!(robot.phase, Phase::Present | Phase::Release) {
                    // The robot gave up (timeout) and took the part back.
                    self.mode = Mode::NeedsPart;
                }
            }
            Mode::Done => {}
        }

        // Targets: gaze and right hand.
        // The third item: the radius of the hand's motion once at its target [m].
        let (gaze_target, hand_target, motion_m) = match self.mode {
            Mode::Working | Mode::Done => {
                (self.assembly_point, self.assembly_point, c.work_motion_m)
            }
            Mode::Excursion { role, .. } => {
                let centre = self.centre(role);
                if role == AreaRole::ToolIdentification {
                    (centre, centre, c.work_motion_m)
                } else {
                    (centre, self.assembly_point, c.work_motion_m)
                }
            }
            Mode::NeedsPart => {
                // Looks at the handover area; the hand stays at the fixture (reaching out
                // early would put it inside the robot's protective separation distance) and
                // keeps handling the assembly while it waits. Assumption: a hand frozen while
                // the handover is pending is exactly what MODEL.md §7 counts as hesitation
                // (H = C ∧ G ∧ low motion), so an operator who merely waits must not freeze;
                // the frozen hand is the hesitation episode's (issue 14, point 2).
                (
                    self.centre(AreaRole::Collaboration),
                    self.assembly_point,
                    c.work_motion_m,
                )
            }
            Mode::Reaching => {
                let tcp = Vec3::new(robot.tcp_m[0], robot.tcp_m[1], robot.tcp_m[2]);
                let shoulder = Vec3::from(c.shoulder_m);
                let d = tcp - shoulder;
                let target = if d.norm() > c.reach_m {
                    shoulder + d * (c.reach_m / d.norm())
                } else {
                    tcp
                };
                (tcp, target, c.hold_motion_m)
            }
        };
        let gaze_target = if hesitating && self.mode != Mode::Done {
            self.centre(AreaRole::Collaboration)
        } else {
            gaze_target
        };
        self.gaze = move_towards(self.gaze, gaze_target, c.gaze_speed_m_s * dt);
        if !hesitating {
            self.hand = move_towards(self.hand, hand_target, c.hand_speed_m_s * dt);
        }
        let mut hand = self.hand;
        if !hesitating && (self.hand - hand_target).norm() < 0.02 {
            hand += work_motion(t, c.work_motion_hz) * motion_m;
        }

        // Cues with noise and dropouts.
        frame.t = t;
        if self.rng.chance(c.burst_p) {
            self.burst_until = t + c.burst_s;
        }
        let occluded = t < self.burst_until;
        let head = Vec3::from(c.head_m) + self.noise3(c.body_noise_m);
        let facing = self.noisy_direction(self.gaze - head, c.facing_noise_rad);
        frame.head = (!self.rng.chance(c.dropout_p)).then_some(HeadCue {
            position: head,
            facing,
            // Fitted: the head cue's confidence with depth (`cue_noise.csv` conf_mean).
            confidence: 1.0,
        });
        let torso = Vec3::from(c.torso_m) + self.noise3(c.body_noise_m);
        let mut torso_facing = (self.gaze - torso).normalize() + Vec3::new(1.0, 0.0, 0.0);
        torso_facing.z = 0.0;
        let torso_facing = self.noisy_direction(torso_facing, c.facing_noise_rad);
        frame.body = (!self.rng.chance(c.dropout_p)).then_some(BodyCue {
            position: torso,
            facing: torso_facing,
            // Fitted: the torso cue's confidence with the hips in view (`cue_noise.csv`).
            confidence: 1.0,
        });
        let right = hand + self.noise3(c.hand_noise_m);
        let left = self.left_hand + self.noise3(c.hand_noise_m);
        let drop_r = occluded || self.rng.chance(c.dropout_p);
        let drop_l = occluded || self.rng.chance(c.dropout_p);
        frame.hands = [
            (!drop_l).then_some(HandCue {
                position: left,
                // Fitted: the hand model's confidence (`cue_noise.csv` 0.987-0.998).
                confidence: 0.99,
            }),
            (!drop_r).then_some(HandCue {
                position: right,
                // Fitted: the hand model's confidence (`cue_noise.csv` 0.987-0.998).
                confidence: 0.99,
            }),
        ];
    }

    /// The right hand's true position [m], workspace frame (for tests).
    #[cfg(test)]
    pub(crate) fn hand_m(&self) -> Vec3 {
        self.hand
    }

    fn noise3(&mut self, sigma: f64) -> Vec3 {
        Vec3::new(self.rng.normal(), self.rng.normal(), self.rng.normal()) * sigma
    }

    fn noisy_direction(&mut self, d: Vec3, sigma: f64) -> Vec3 {
        let n = d.norm();
        let d = if n > 1e-9 {
            d / n
        } else {
            Vec3::new(1.0, 0.0, 0.0)
        };
        (d + self.noise3(sigma)).normalize()
    }
}

fn move_towards(from: Vec3, to: Vec3, max_step: f64) -> Vec3 {
    let d = to - from;
    let n = d.norm();
    if n <= max_step || n < 1e-12 {
        to
    } else {
        from + d * (max_step / n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn workspace() -> Workspace {
        Workspace::from_toml_file(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/config/example-workspace.toml"
        ))
        .unwrap()
    }

    fn idle_robot() -> RobotView {
        RobotView {
            phase: Phase::Idle,
            tcp_m: [1.2, 1.0, 1.0],
            tcp_speed_m_s: 0.0,
            tcp_peak_acc_m_s2: 0.0,
        }
    }

    #[test]
    fn same_seed_same_cues_and_different_seed_differs() {
        let ws = workspace();
        let run = |seed| {
            let mut op =
                SimulatedOperator::new(Level::L2, &ws, seed, OperatorResponse::default()).unwrap();
            let mut frame = CueFrame::empty(0.0);
            let mut out = Vec::new();
            for k in 0..300 {
                op.step(k as f64 / 30.0, &idle_robot(), &mut frame);
                out.push(format!("{:?}", frame));
            }
            out
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7), run(8));
    }

    #[test]
    fn operator_needs_the_first_part_after_its_first_segment_and_reaches_for_a_presented_tcp() {
        let ws = workspace();
        let mut op =
            SimulatedOperator::new(Level::L1, &ws, 1, OperatorResponse::default()).unwrap();
        let mut frame = CueFrame::empty(0.0);
        let mut robot = idle_robot();
        let mut needed_at = None;
        for k in 0..(30 * 200) {
            let t = k as f64 / 30.0;
            op.step(t, &robot, &mut frame);
            if op
                .events()
                .contains(&TrialEvent::OperatorNeedsPart { handover: 1 })
            {
                needed_at = Some(t);
                robot.phase = Phase::Present;
                robot.tcp_m = [0.7, 0.4, 1.0];
            }
            if needed_at.is_some_and(|n| t > n + 6.0) {
                break;
            }
        }
        let n = needed_at.expect("needs a part");
        assert!(n > 20.0 && n < 120.0, "{n}");
        // Within reach: the hand got to the TCP (hesitations last seconds, not 6 s in total
        // at L1's rates, almost surely; this seed is checked).
        assert!((op.hand_m() - Vec3::new(0.7, 0.4, 1.0)).norm() < 0.05);
        op.release_confirmed();
        assert_eq!(op.events()[0], TrialEvent::Grasped { handover: 1 });
    }

    /// The response effect sizes act (issue 14, point 4): on a fixed seed, an L2 operator who
    /// needs a part and watches the robot approach at the collaborative cap (0.25 m/s, 0.5
    /// m/s² peak) for 60 s hesitates (ground truth) longer the higher `k_speed`, and with every
    /// response off (k = 0, the base rate only) less than with the shipped values. By the
    /// model: stress 0, 2.0 and 6.5 (k_speed 0, 1.5, 6.0 with k_acc 0, 1.0, 1.0) give rates
    /// 0.06, 0.18 and 0.45 /s and median durations 1.5, 3.0 and 6.4 s.
    #[test]
    fn a_higher_k_speed_gives_more_ground_truth_hesitation_on_a_fixed_seed() {
        let ws = workspace();
        let hesitating_s = |response: OperatorResponse| {
            let mut op = SimulatedOperator::new(Level::L2, &ws, 5, response).unwrap();
            let mut frame = CueFrame::empty(0.0);
            let dt = 1.0 / 30.0;
            let mut k = 0;
            // Until the first part is needed (idle robot: no response).
            while op.awaiting().is_none() {
                op.step(k as f64 * dt, &idle_robot(), &mut frame);
                k += 1;
                assert!(k < 30 * 300, "needs a part within 300 s");
            }
            let approaching = RobotView {
                phase: Phase::Approach,
                tcp_m: [1.2, 1.0, 1.0],
                tcp_speed_m_s: 0.25,
                tcp_peak_acc_m_s2: 0.5,
            };
            let mut frozen = 0.0;
            for _ in 0..(30 * 60) {
                op.step(k as f64 * dt, &approaching, &mut frame);
                k += 1;
                if op.hesitating() {
                    frozen += dt;
                }
            }
            frozen
        };
        let shipped = OperatorResponse::default();
        let off = hesitating_s(OperatorResponse {
            k_speed: 0.0,
            k_acc: 0.0,
            ..shipped
        });
        let base = hesitating_s(shipped);
        let high = hesitating_s(OperatorResponse {
            k_speed: 6.0,
            ..shipped
        });
        assert!(off < base && base < high, "{off} {base} {high} s");
        // Clearly: a large share of the minute more.
        assert!(
            high - base > 10.0 && base - off > 5.0,
            "{off} {base} {high} s"
        );
    }

    /// The fitted hand noise lets the assessment see a frozen hand (issue 14, point 1): the
    /// noise of a still simulated hand, through the assessment's own hesitation filter
    /// (`[hesitation.one_euro]`, 30 Hz), stays below v_min for a whole t_min (0.3 s, 9 frames)
    /// in at least 90 % of the windows (`docs/calibration/operator_fit.md` measured 96.5 % with
    /// another generator). With the 5 mm used before the fit it never does, so the check can
    /// fail.
    #[test]
    fn a_frozen_hand_with_the_fitted_noise_is_low_motion_for_the_assessment() {
        use assess::AssessConfig;
        use assess::filter::OneEuro3;
        let h = AssessConfig::default().hesitation;
        let share_below = |sigma: f64| {
            let mut op =
                SimulatedOperator::new(Level::L2, &workspace(), 3, OperatorResponse::default())
                    .unwrap();
            let mut f = OneEuro3::new(h.one_euro);
            let dt = 1.0 / 30.0;
            let hand = Vec3::new(0.5, 0.3, 0.8);
            let mut prev = f.filter((hand + op.noise3(sigma)).into(), 0.0);
            let speeds: Vec<f64> = (0..3000)
                .map(|_| {
                    let now = f.filter((hand + op.noise3(sigma)).into(), dt);
                    let v = (Vec3::from(now) - Vec3::from(prev)).norm() / dt;
                    prev = now;
                    v
                })
                .skip(30) // the filter's first second
                .collect();
            let frames = (h.min_duration_s * 30.0).round() as usize;
            let windows: Vec<&[f64]> = speeds.windows(frames).collect();
            let low = windows
                .iter()
                .filter(|w| w.iter().all(|v| *v < h.v_min_m_s))
                .count();
            low as f64 / windows.len() as f64
        };
        let fitted = share_below(COMMON.hand_noise_m);
        assert!(fitted >= 0.9, "fitted {} m: {fitted}", COMMON.hand_noise_m);
        let before = share_below(0.005);
        assert!(before < 0.01, "5 mm: {before}");
    }

    /// The hold motion (`hold_motion_m` at `work_motion_hz`) with the fitted hand noise,
    /// through the assessment's One-Euro filter at 30 Hz, has the median filtered speed of the
    /// real KTH taker's hold, v_h 0.077 m/s (`docs/calibration/kth_kinematics.md`, stillness
    /// table), within ±15 %; the working motion (`work_motion_m`) filters above v_max, so a
    /// waiting, working hand is never low motion.
    #[test]
    fn the_hold_motion_filters_to_the_measured_kth_hold_speed() {
        use assess::AssessConfig;
        use assess::filter::OneEuro3;
        let h = AssessConfig::default().hesitation;
        let median_speed = |radius: f64| {
            let mut op =
                SimulatedOperator::new(Level::L2, &workspace(), 5, OperatorResponse::default())
                    .unwrap();
            let mut f = OneEuro3::new(h.one_euro);
            let dt = 1.0 / 30.0;
            let at = |k: usize, op: &mut SimulatedOperator| {
                let t = k as f64 * dt;
                Vec3::new(0.5, 0.3, 0.8)
                    + work_motion(t, COMMON.work_motion_hz) * radius
                    + op.noise3(COMMON.hand_noise_m)
            };
            let mut prev = f.filter(at(0, &mut op).into(), 0.0);
            let mut speeds: Vec<f64> = (1..900)
                .map(|k| {
                    let now = f.filter(at(k, &mut op).into(), dt);
                    let v = (Vec3::from(now) - Vec3::from(prev)).norm() / dt;
                    prev = now;
                    v
                })
                .skip(30)
                .collect();
            speeds.sort_by(f64::total_cmp);
            speeds[speeds.len() / 2]
        };
        let hold = median_speed(COMMON.hold_motion_m);
        assert!(
            (hold - 0.077).abs() <= 0.15 * 0.077,
            "hold v_h median {hold}"
        );
        let work = median_speed(COMMON.work_motion_m);
        assert!(work > h.v_max_m_s, "working v_h median {work}");
    }
}
