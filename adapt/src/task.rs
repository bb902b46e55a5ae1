//! The handover task: a state machine that fetches a part, hands it to the operator and retreats.
//!
//! # Phases
//! ```text
//! Idle ─start─► Fetch ─gripped + start delay─► [WaitForAttention] ─► Approach ─arrived─► Present
//!                                                                                        │    │
//!                          Done ◄─arrived─ Retreat ◄─release confirmed─ Release ◄─grasp─┘    │
//!                                             ▲                                              │
//!                                             └──────────────── timeout (part returned) ─────┘
//! ```
//! - **Idle**: nothing to do; [`HandoverTask::start`] arms the task.
//! - **Fetch**: move to the pick pose, close the gripper (`grip_dwell_s`), then hold for the
//!   adaptation's start delay.
//! - **WaitForAttention**: entered only when the adaptation asks for it and the operator's
//!   attention is not on the robot; the robot holds the part at the pick pose until it is.
//! - **Approach**: move to the handover pose in front of the operator.
//! - **Present**: hold the part at the handover pose. The operator's grasp is detected when a hand
//!   stays within `grasp_radius_m` (r_grasp) of the TCP for `grasp_time_s` (t_grasp) without a
//!   break; a hand passing by briefly does not count. After the present timeout (the input's
//!   `present_timeout_s` when the presentation starts, else the config's) without a grasp
//!   the robot gives up and returns the part: Present → Retreat, with a
//!   [`TaskEventKind::PresentTimeout`] event, and the retreat goes back to the pick pose.
//! - **Release**: the gripper opens; the release is confirmed after `release_dwell_s`.
//! - **Retreat**: move to the home pose (or back to the pick pose after a timeout).
//! - **Done**: finished; [`HandoverTask::reset`] returns to Idle for another handover.
//!
//! # Robot context for the assessment
//! - C(t) ([`HandoverTask::collaborating`]): true during Approach, Present and Release.
//! - G(t) ([`HandoverTask::incomplete`]): true until the release is confirmed. After a timeout
//!   the release never happens, so G stays true (the operation was not completed) until
//!   [`HandoverTask::reset`].
//!
//! # Real time
//! Time is injected (`now_s` in [`TaskInput`]); nothing reads a clock. [`HandoverTask::step`]
//! allocates nothing: events go into a caller-owned, fixed-capacity [`EventBuffer`].
//!
//! # Example
//! ```
//! use adapt::task::{EventBuffer, HandoverTask, Phase, TaskConfig, TaskInput};
//! let mut task = HandoverTask::new(TaskConfig::example());
//! let mut events = EventBuffer::<8>::new();
//! task.start();
//! task.step(&TaskInput::at(0.0), &mut events);
//! assert_eq!(task.phase(), Phase::Fetch);
//! assert!(!task.collaborating() && task.incomplete());
//! ```

use std::fmt;

use robot_io::Joints;
use serde::Deserialize;

use crate::error::{non_negative, positive};
use crate::{AdaptError, Result};

/// The phases of a handover (see the module docs for the transitions).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Phase {
    /// Nothing to do yet.
    #[default]
    Idle,
    /// Moving to the pick pose and gripping the part.
    Fetch,
    /// Holding the part until the operator's attention is on the robot.
    WaitForAttention,
    /// Moving to the handover pose.
    Approach,
    /// Holding the part at the handover pose for the operator to grasp.
    Present,
    /// Opening the gripper.
    Release,
    /// Moving away (home, or back to the pick pose after a timeout).
    Retreat,
    /// Finished.
    Done,
}

impl Phase {
    /// All phases, in task order.
    pub const ALL: [Phase; 8] = [
        Phase::Idle,
        Phase::Fetch,
        Phase::WaitForAttention,
        Phase::Approach,
        Phase::Present,
        Phase::Release,
        Phase::Retreat,
        Phase::Done,
    ];

    /// The phase's name in snake case, as logs write it.
    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Idle => "idle",
            Phase::Fetch => "fetch",
            Phase::WaitForAttention => "wait_for_attention",
            Phase::Approach => "approach",
            Phase::Present => "present",
            Phase::Release => "release",
            Phase::Retreat => "retreat",
            Phase::Done => "done",
        }
    }

    /// C(t) for this phase: true during Approach, Present and Release.
    pub fn is_collaborating(self) -> bool {
        matches!(self, Phase::Approach | Phase::Present | Phase::Release)
    }
}

impl fmt::Display for Phase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// What happened, in a [`TaskEvent`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TaskEventKind {
    /// The task moved from one phase to another.
    PhaseChanged {
        /// The phase left.
        from: Phase,
        /// The phase entered.
        to: Phase,
    },
    /// The gripper closed on the part at the pick pose.
    PartGripped,
    /// A hand stayed within r_grasp of the TCP for t_grasp.
    GraspDetected {
        /// Which hand: 0 left, 1 right (indices of [`TaskInput::hands_m`]).
        hand: usize,
    },
    /// The gripper opened and the operator holds the part alone.
    ReleaseConfirmed,
    /// No grasp within `present_timeout_s`: the robot returns the part.
    PresentTimeout,
}

/// A handover event with its time stamp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskEvent {
    /// When it happened: the `now_s` of the step that saw it [s].
    pub t_s: f64,
    /// What happened.
    pub kind: TaskEventKind,
}

/// A caller-owned, fixed-capacity buffer of [`TaskEvent`]s: pushing never allocates. When full,
/// further events are counted in [`EventBuffer::dropped`] and discarded. The caller drains it
/// (reads, then [`EventBuffer::clear`]) as often as it needs; one step emits at most three events.
#[derive(Debug, Clone)]
pub struct EventBuffer<const N: usize> {
    events: [TaskEvent; N],
    len: usize,
    dropped: u64,
}

impl<const N: usize> EventBuffer<N> {
    /// An empty buffer of capacity `N`.
    pub fn new() -> Self {
        Self {
            events: [TaskEvent {
                t_s: 0.0,
                kind: TaskEventKind::PartGripped,
            }; N],
            len: 0,
            dropped: 0,
        }
    }

    /// Append an event; returns false (and counts it as dropped) when the buffer is full.
    pub fn push(&mut self, event: TaskEvent) -> bool {
        match self.events.get_mut(self.len) {
            Some(slot) => {
                *slot = event;
                self.len += 1;
                true
            }
            None => {
                self.dropped = self.dropped.saturating_add(1);
                false
            }
        }
    }

    /// The events held, oldest first.
    pub fn as_slice(&self) -> &[TaskEvent] {
        self.events.get(..self.len).unwrap_or(&[])
    }

    /// Iterate over the events held, oldest first.
    pub fn iter(&self) -> std::slice::Iter<'_, TaskEvent> {
        self.as_slice().iter()
    }

    /// Number of events held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether no event is held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Capacity [events].
    pub fn capacity(&self) -> usize {
        N
    }

    /// Events discarded because the buffer was full, since construction.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Forget the events held (the dropped count is kept).
    pub fn clear(&mut self) {
        self.len = 0;
    }
}

impl<const N: usize> Default for EventBuffer<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// A pose as the config file gives it: joint space, or Cartesian (flange position and rotation
/// vector in the base frame, as UR's `p[x, y, z, rx, ry, rz]`, solved by IK).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPose {
    /// Joint positions [rad], base to wrist 3.
    #[serde(default)]
    pub joints_rad: Option<Joints>,
    /// Flange position in the base frame [m].
    #[serde(default)]
    pub position_m: Option<[f64; 3]>,
    /// Flange orientation as a rotation vector in the base frame [rad].
    #[serde(default)]
    pub rotation_vector_rad: Option<[f64; 3]>,
}

/// The poses of a handover as the config file gives them.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPoses {
    /// Where the robot starts and ends. Cartesian IK takes the branch nearest the elbow-up,
    /// wrist-down reference `[0, −π/2, π/2, −π/2, −π/2, 0]` rad.
    pub home: RawPose,
    /// Where the part is picked (Cartesian IK: branch nearest home).
    pub pick: RawPose,
    /// Where the part is presented, in front of the operator (Cartesian IK: branch nearest pick).
    pub handover: RawPose,
}

/// The task's configuration as the config file (`[task]`) gives it; see [`TaskConfig`] for the
/// meaning and rules of each key.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawTaskConfig {
    /// See [`TaskConfig::grasp_radius_m`].
    pub grasp_radius_m: f64,
    /// See [`TaskConfig::grasp_time_s`].
    pub grasp_time_s: f64,
    /// See [`TaskConfig::present_timeout_s`].
    pub present_timeout_s: f64,
    /// See [`TaskConfig::grip_dwell_s`].
    pub grip_dwell_s: f64,
    /// See [`TaskConfig::release_dwell_s`].
    pub release_dwell_s: f64,
    /// The poses.
    pub poses: RawPoses,
}

/// The validated task configuration: poses in joint space, timings and the grasp detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskConfig {
    /// Home pose [rad]: start and end of a handover.
    pub home_q_rad: Joints,
    /// Pick pose [rad].
    pub pick_q_rad: Joints,
    /// Handover pose [rad], in front of the operator.
    pub handover_q_rad: Joints,
    /// r_grasp: a hand within this distance of the TCP may be grasping [m], > 0.
    pub grasp_radius_m: f64,
    /// t_grasp: how long a hand must stay within r_grasp, without a break [s], in
    /// (0, [`MAX_TASK_TIME_S`]].
    pub grasp_time_s: f64,
    /// How long the robot presents before it returns the part [s], > t_grasp and
    /// ≤ [`MAX_TASK_TIME_S`].
    pub present_timeout_s: f64,
    /// Time for the gripper to close at the pick pose [s], in [0, [`MAX_TASK_TIME_S`]].
    pub grip_dwell_s: f64,
    /// Time for the gripper to open before the release is confirmed [s], in
    /// [0, [`MAX_TASK_TIME_S`]].
    pub release_dwell_s: f64,
}

/// The elbow-up, wrist-down reference for IK of a Cartesian home pose [rad].
pub const IK_REFERENCE_Q_RAD: Joints = [
    0.0,
    -std::f64::consts::FRAC_PI_2,
    std::f64::consts::FRAC_PI_2,
    -std::f64::consts::FRAC_PI_2,
    -std::f64::consts::FRAC_PI_2,
    0.0,
];

/// Longest `grasp_time_s`, `present_timeout_s`, `grip_dwell_s` and `release_dwell_s` [s]:
/// 600 s, a whole shipped trial; longer would stall the task for the rest of it.
pub const MAX_TASK_TIME_S: f64 = 600.0;

/// UR5e joint position limit [rad]: ±2π.
const JOINT_LIMIT_RAD: f64 = std::f64::consts::TAU;

impl TaskConfig {
    /// A UR5e-plausible example, all in joint space (`config/handover.toml` gives the pick pose
    /// in Cartesian form instead). With the operator standing on the robot's −x side:
    /// - home `[0, −π/2, π/2, −π/2, −π/2, 0]`: flange at (−0.49, −0.13, 0.49) m, tool down;
    /// - pick `[−1.0, −1.2, 2.1, −2.47, −π/2, 0.57]`: flange at (−0.38, 0.35, 0.15) m, tool down,
    ///   to the robot's side just above the table;
    /// - handover `[0, −0.9, 1.3, −1.97, −π/2, 0]`: flange at (−0.73, −0.13, 0.24) m, tool down,
    ///   reaching out towards the operator at about hand height.
    pub fn example() -> TaskConfig {
        use std::f64::consts::FRAC_PI_2;
        TaskConfig {
            home_q_rad: IK_REFERENCE_Q_RAD,
            pick_q_rad: [-1.0, -1.2, 2.1, -2.47, -FRAC_PI_2, 0.57],
            handover_q_rad: [0.0, -0.9, 1.3, -1.97, -FRAC_PI_2, 0.0],
            grasp_radius_m: 0.08,
            grasp_time_s: 0.3,
            present_timeout_s: 8.0,
            grip_dwell_s: 0.4,
            release_dwell_s: 0.3,
        }
    }

    /// Validate the timings, the grasp detector and joint-space poses.
    pub fn validate(&self) -> Result<()> {
        for (key, q) in [
            ("poses.home", &self.home_q_rad),
            ("poses.pick", &self.pick_q_rad),
            ("poses.handover", &self.handover_q_rad),
        ] {
            check_joints(key, q)?;
        }
        positive("grasp_radius_m", self.grasp_radius_m)?;
        positive("grasp_time_s", self.grasp_time_s)?;
        positive("present_timeout_s", self.present_timeout_s)?;
        for (key, v) in [
            ("grasp_time_s", self.grasp_time_s),
            ("present_timeout_s", self.present_timeout_s),
            ("grip_dwell_s", self.grip_dwell_s),
            ("release_dwell_s", self.release_dwell_s),
        ] {
            if v > MAX_TASK_TIME_S {
                return Err(invalid(
                    key,
                    format!("must be at most {MAX_TASK_TIME_S} s, got {v} s"),
                ));
            }
        }
        if self.present_timeout_s <= self.grasp_time_s {
            return Err(invalid(
                "present_timeout_s",
                format!(
                    "must exceed grasp_time_s ({} s), got {} s",
                    self.grasp_time_s, self.present_timeout_s
                ),
            ));
        }
        non_negative("grip_dwell_s", self.grip_dwell_s)?;
        non_negative("release_dwell_s", self.release_dwell_s)?;
        Ok(())
    }

    /// Validate a raw config, solving Cartesian poses with `solve_ik(pose, seed)`, which returns
    /// the IK branch nearest `seed` for the flange pose `[x, y, z, rx, ry, rz]` ([m], [rad]) or
    /// `None` when the pose is unreachable. `TryFrom<&RawTaskConfig>` uses [`crate::ik::nearest`].
    pub fn from_raw_with(
        raw: &RawTaskConfig,
        mut solve_ik: impl FnMut(&[f64; 6], &Joints) -> Option<Joints>,
    ) -> Result<TaskConfig> {
        let home = resolve_pose(
            "poses.home",
            &raw.poses.home,
            &IK_REFERENCE_Q_RAD,
            &mut solve_ik,
        )?;
        let pick = resolve_pose("poses.pick", &raw.poses.pick, &home, &mut solve_ik)?;
        let handover = resolve_pose("poses.handover", &raw.poses.handover, &pick, &mut solve_ik)?;
        let cfg = TaskConfig {
            home_q_rad: home,
            pick_q_rad: pick,
            handover_q_rad: handover,
            grasp_radius_m: raw.grasp_radius_m,
            grasp_time_s: raw.grasp_time_s,
            present_timeout_s: raw.present_timeout_s,
            grip_dwell_s: raw.grip_dwell_s,
            release_dwell_s: raw.release_dwell_s,
        };
        cfg.validate()?;
        Ok(cfg)
    }
}

impl TryFrom<&RawTaskConfig> for TaskConfig {
    type Error = AdaptError;

    /// Validate, solving Cartesian poses with [`crate::ik::nearest`] (flange poses; the branch
    /// nearest the seed described in [`RawPoses`]).
    fn try_from(raw: &RawTaskConfig) -> Result<TaskConfig> {
        TaskConfig::from_raw_with(raw, |pose, seed| {
            crate::ik::nearest(seed, &robot_io::kinematics::pose_from_vector(pose)).ok()
        })
    }
}

impl TryFrom<RawTaskConfig> for TaskConfig {
    type Error = AdaptError;

    /// As `TryFrom<&RawTaskConfig>`.
    fn try_from(raw: RawTaskConfig) -> Result<TaskConfig> {
        TaskConfig::try_from(&raw)
    }
}

fn resolve_pose(
    key: &'static str,
    raw: &RawPose,
    seed: &Joints,
    solve_ik: &mut impl FnMut(&[f64; 6], &Joints) -> Option<Joints>,
) -> Result<Joints> {
    match (raw.joints_rad, raw.position_m, raw.rotation_vector_rad) {
        (Some(q), None, None) => {
            check_joints(key, &q)?;
            Ok(q)
        }
        (None, Some(p), Some(r)) => {
            let pose = [p[0], p[1], p[2], r[0], r[1], r[2]];
            if !pose.iter().all(|v| v.is_finite()) {
                return Err(invalid(
                    key,
                    "position_m and rotation_vector_rad must be finite",
                ));
            }
            let q = solve_ik(&pose, seed).ok_or(AdaptError::UnreachablePose { pose: key })?;
            check_joints(key, &q)?;
            Ok(q)
        }
        _ => Err(invalid(
            key,
            "give either joints_rad, or position_m with rotation_vector_rad",
        )),
    }
}

fn check_joints(key: &'static str, q: &Joints) -> Result<()> {
    if q.iter()
        .all(|v| v.is_finite() && v.abs() <= JOINT_LIMIT_RAD)
    {
        Ok(())
    } else {
        Err(invalid(
            key,
            format!("joints must be finite and within ±2π rad, got {q:?}"),
        ))
    }
}

fn invalid(key: &'static str, rule: impl Into<String>) -> AdaptError {
    AdaptError::InvalidValue {
        key: key.to_owned(),
        rule: rule.into(),
    }
}

/// What the task sees each step. Built by the controller from the robot state, the motion
/// generator and the adaptation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskInput {
    /// The current time [s] (injected; any monotonic clock).
    pub now_s: f64,
    /// TCP (flange) position in the base frame [m].
    pub tcp_position_m: [f64; 3],
    /// The robot has arrived at the current target ([`HandoverTask::target_q_rad`]) and stands
    /// still there.
    pub motion_finished: bool,
    /// The operator's hands in the base frame [m]: 0 left, 1 right; `None` when not tracked.
    pub hands_m: [Option<[f64; 3]>; 2],
    /// The adaptation asks to wait for the operator's attention before the approach.
    pub wait_for_attention: bool,
    /// The operator's attention is on the robot now.
    pub attention_on_robot: bool,
    /// Hold this long after the part is gripped before the handover starts [s] (≥ 0; a
    /// non-finite or negative value counts as 0).
    pub start_delay_s: f64,
    /// Present this long before returning the part [s], read when the presentation starts;
    /// `None`, or a value that is not finite or not above `grasp_time_s` (no grasp could be
    /// detected in it): the config's `present_timeout_s`.
    pub present_timeout_s: Option<f64>,
}

impl TaskInput {
    /// An input at `now_s` with nothing happening: TCP at the origin, motion not finished, no
    /// hands, no attention gating, no start delay.
    pub fn at(now_s: f64) -> TaskInput {
        TaskInput {
            now_s,
            tcp_position_m: [0.0; 3],
            motion_finished: false,
            hands_m: [None, None],
            wait_for_attention: false,
            attention_on_robot: false,
            start_delay_s: 0.0,
            present_timeout_s: None,
        }
    }
}

/// The handover state machine (see the module docs). Build it once; [`HandoverTask::step`]
/// allocates nothing.
#[derive(Debug, Clone)]
pub struct HandoverTask {
    cfg: TaskConfig,
    phase: Phase,
    /// When the current phase was entered [s]; `None` until the first step after a change.
    phase_since_s: Option<f64>,
    start_requested: bool,
    /// When the part is (or will be) gripped: arrival at the pick pose + grip dwell [s].
    gripped_at_s: Option<f64>,
    gripped_reported: bool,
    /// Since when each hand has been within r_grasp of the TCP without a break [s].
    hand_near_since_s: [Option<f64>; 2],
    release_confirmed: bool,
    returned: bool,
    /// The present timeout of the current presentation [s], fixed when it starts.
    present_timeout_s: f64,
}

impl HandoverTask {
    /// A task in Idle. `cfg` should come from [`TaskConfig::validate`] or
    /// [`TaskConfig::from_raw_with`]; use [`HandoverTask::try_new`] to validate here.
    pub fn new(cfg: TaskConfig) -> HandoverTask {
        HandoverTask {
            cfg,
            phase: Phase::Idle,
            phase_since_s: None,
            start_requested: false,
            gripped_at_s: None,
            gripped_reported: false,
            hand_near_since_s: [None, None],
            release_confirmed: false,
            returned: false,
            present_timeout_s: cfg.present_timeout_s,
        }
    }

    /// Validate `cfg`, then [`HandoverTask::new`].
    pub fn try_new(cfg: TaskConfig) -> Result<HandoverTask> {
        cfg.validate()?;
        Ok(Self::new(cfg))
    }

    /// The configuration.
    pub fn config(&self) -> &TaskConfig {
        &self.cfg
    }

    /// Arm the task: the next step leaves Idle for Fetch. Ignored outside Idle.
    pub fn start(&mut self) {
        if self.phase == Phase::Idle {
            self.start_requested = true;
        }
    }

    /// Back to Idle for another handover (keeps the config). Allocates nothing.
    pub fn reset(&mut self) {
        *self = HandoverTask::new(self.cfg);
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// C(t): a collaboration period is active (Approach, Present or Release).
    pub fn collaborating(&self) -> bool {
        self.phase.is_collaborating()
    }

    /// G(t): the handover is incomplete (the release has not been confirmed).
    pub fn incomplete(&self) -> bool {
        !self.release_confirmed
    }

    /// Whether the part was returned after a Present timeout.
    pub fn part_returned(&self) -> bool {
        self.returned
    }

    /// When the current phase was entered [s], once a step has run in it.
    pub fn phase_since_s(&self) -> Option<f64> {
        self.phase_since_s
    }

    /// Where the robot should go in the current phase [rad]; `None` in Idle and Done (hold where
    /// it is).
    pub fn target_q_rad(&self) -> Option<&Joints> {
        match self.phase {
            Phase::Idle | Phase::Done => None,
            Phase::Fetch | Phase::WaitForAttention => Some(&self.cfg.pick_q_rad),
            Phase::Approach | Phase::Present | Phase::Release => Some(&self.cfg.handover_q_rad),
            Phase::Retreat if self.returned => Some(&self.cfg.pick_q_rad),
            Phase::Retreat => Some(&self.cfg.home_q_rad),
        }
    }

    /// Advance the task to `input.now_s`, pushing what happened into `events`. At most one phase
    /// change per step. Allocates nothing; a non-finite `now_s` is ignored.
    pub fn step<const N: usize>(&mut self, input: &TaskInput, events: &mut EventBuffer<N>) {
        let now = input.now_s;
        if !now.is_finite() {
            return;
        }
        let since = *self.phase_since_s.get_or_insert(now);
        let in_phase = now - since;
        let mut emit = |kind| {
            events.push(TaskEvent { t_s: now, kind });
        };
        let next = match self.phase {
            Phase::Idle => self.start_requested.then_some(Phase::Fetch),
            Phase::Fetch => {
                if self.gripped_at_s.is_none() && input.motion_finished {
                    // Arrived: the gripper closes over grip_dwell_s, counted from arrival.
                    self.gripped_at_s = Some(now + self.cfg.grip_dwell_s);
                }
                match self.gripped_at_s {
                    Some(t) if now >= t => {
                        if !self.gripped_reported {
                            self.gripped_reported = true;
                            emit(TaskEventKind::PartGripped);
                        }
                        let delay = sanitize_delay(input.start_delay_s);
                        if now - t >= delay {
                            Some(if input.wait_for_attention && !input.attention_on_robot {
                                Phase::WaitForAttention
                            } else {
                                Phase::Approach
                            })
                        } else {
                            None
                        }
                    }
                    _ => None,
                }
            }
            Phase::WaitForAttention => {
                (!input.wait_for_attention || input.attention_on_robot).then_some(Phase::Approach)
            }
            Phase::Approach => {
                let grasp = self.cfg.grasp_time_s;
                let t = input
                    .present_timeout_s
                    .filter(|t| t.is_finite() && *t > grasp);
                self.present_timeout_s = t.unwrap_or(self.cfg.present_timeout_s);
                input.motion_finished.then_some(Phase::Present)
            }
            Phase::Present => {
                let grasp = self.update_grasp(input);
                if let Some(hand) = grasp {
                    emit(TaskEventKind::GraspDetected { hand });
                    Some(Phase::Release)
                } else if in_phase >= self.present_timeout_s {
                    emit(TaskEventKind::PresentTimeout);
                    self.returned = true;
                    Some(Phase::Retreat)
                } else {
                    None
                }
            }
            Phase::Release => {
                if in_phase >= self.cfg.release_dwell_s {
                    emit(TaskEventKind::ReleaseConfirmed);
                    self.release_confirmed = true;
                    Some(Phase::Retreat)
                } else {
                    None
                }
            }
            Phase::Retreat => input.motion_finished.then_some(Phase::Done),
            Phase::Done => None,
        };
        if let Some(to) = next {
            emit(TaskEventKind::PhaseChanged {
                from: self.phase,
                to,
            });
            self.enter(to, now);
        }
    }

    fn enter(&mut self, to: Phase, now: f64) {
        self.phase = to;
        self.phase_since_s = Some(now);
        self.hand_near_since_s = [None, None];
    }

    /// Update the per-hand grasp timers; the hand whose timer reached t_grasp, if any.
    fn update_grasp(&mut self, input: &TaskInput) -> Option<usize> {
        let r2 = self.cfg.grasp_radius_m * self.cfg.grasp_radius_m;
        let tcp = input.tcp_position_m;
        let mut grasped = None;
        for (i, (since, hand)) in self
            .hand_near_since_s
            .iter_mut()
            .zip(input.hands_m.iter())
            .enumerate()
        {
            let near = hand.is_some_and(|h| {
                let d2 =
                    (h[0] - tcp[0]).powi(2) + (h[1] - tcp[1]).powi(2) + (h[2] - tcp[2]).powi(2);
                d2 <= r2
            });
            if near {
                let t0 = *since.get_or_insert(input.now_s);
                if grasped.is_none() && input.now_s - t0 >= self.cfg.grasp_time_s {
                    grasped = Some(i);
                }
            } else {
                *since = None;
            }
        }
        grasped
    }
}

fn sanitize_delay(d: f64) -> f64 {
    if d.is_finite() && d > 0.0 { d } else { 0.0 }
}
