//! # safety: the supervisor every robot command passes
//!
//! [`Supervisor<R: Robot>`](Supervisor) owns the robot and is the only path to
//! `Robot::send`: [`Supervisor::step`] judges each command against the limits, the latest
//! robot state and a [`WorldView`] (the operator's tracked body, perception age, whether a
//! collaboration period C(t) is active), and sends it unchanged, scaled down, or replaced by
//! a stop. Commands are sent only as a [`SafeCommand`], which only the supervisor can build;
//! the robot cannot be reached mutably from outside, and its state is read through
//! [`Supervisor::read_state`].
//!
//! Main types:
//! - [`Supervisor`]: `new(robot, config)`, `read_state`, `step`, `reset`;
//! - [`SupervisorConfig`] (UR5e defaults in [`SupervisorConfig::ur5e`]) built from validated
//!   newtypes: [`JointLimits`], [`JointRateLimits`], [`SpeedLimit`], [`SpeedScale`],
//!   [`CyclePeriod`], [`WorkspaceBox`], [`SeparationParams`], [`StalenessLimits`];
//! - [`Verdict`]: `Passed`, `Reduced { scale, violation }`, `Stopped { violation }`,
//!   `Halted { violation }`; each [`Violation`] names its [`Requirement`];
//! - [`Counters`]: verdicts per reaction and per requirement;
//! - [`separation::protective_distance_m`]: ISO/TS 15066's S_p (the formula and
//!   [`SeparationParams`] are `robot_io::separation`'s, shared with the planner);
//! - separation geometry from `robot_io::geometry`, also shared with the planner: the arm,
//!   gripper and carried part as capsules ([`ArmModel`], [`ArmLink`]) and the operator's body
//!   ([`HumanBody`], [`BodyModel`], [`BodyPart`]);
//! - [`points::arm_points`]: TCP, wrist and elbow from UR5e forward kinematics (the workspace
//!   box and the TCP speed).
//!
//! # Reactions
//! - **pass**: sent unchanged;
//! - **pass with reduced speed**: the velocity of the command (servoJ: the step from the
//!   previous target; speedJ: `qd`) is scaled by one factor in [0, 1] so every speed cap
//!   holds; a speedJ acceleration above the limit is clamped. When a cap drops below the
//!   current speed (collaboration begins, perception goes stale), a servo motion
//!   decelerates at the acceleration limit, as fast as a stop would, until it is under the
//!   cap;
//! - **stop**: replaced by `JointCommand::Stop { decel }` at the configured stop deceleration
//!   (π rad/s² on a UR5e); the next cycle is judged afresh;
//! - **halt and latch**: a stop, now and every cycle, until [`Supervisor::reset`] succeeds,
//!   which it does only once the cause is gone.
//!
//! # Requirements
//! Checked in this order each cycle; the first stop or halt wins, and a reduction names the
//! cap that bound it. Defaults are [`SupervisorConfig::ur5e`]'s.
//!
//! | ID | requirement | threshold (default) | reaction | test |
//! |---|---|---|---|---|
//! | SAF-REQ-010 | the robot reports safety mode other than NORMAL, or a protective / emergency / stopped-due-to-safety bit | `safety_mode != 1`, bits 2, 7, 10 | halt and latch | `saf_req_010_robot_safety_stop_halts_and_latches`, `saf_req_010_fault_injection_protective_stop` |
//! | SAF-REQ-009 | robot-state staleness (a `reset()` does not clear it: only a new state does) | > 3 cycles without a new controller timestamp | stop | `saf_req_009_robot_state_staleness` |
//! | SAF-REQ-001 | non-finite or malformed command or input (robot state, world view, servoJ lookahead ∉ [0.03, 0.2] s or gain ∉ [100, 2000], speedJ acc ≤ 0, stop decel ≤ 0) | any NaN/∞ | stop (the robot holds) | `saf_req_001_non_finite_values_are_rejected`, `saf_req_001_fault_injection_nan_target` |
//! | SAF-REQ-008 | perception staleness | age > 0.2 s; > 1 s | reduce the speed caps ×0.25; stop | `saf_req_008_perception_staleness`, `saf_req_008_fault_injection_perception_freeze` |
//! | SAF-REQ-003 | joint speed implied by the command (servoJ: step / the controller time since the previous servo command, 1 to `command_period_cycles` (4 on a UR5e: its servo extrapolation bound + 1) cycles of 2 ms; speedJ: `qd`) | π rad/s | reduce | `saf_req_003_joint_speed_limit`, `saf_req_003_ramp_commanded_every_third_cycle_is_judged_over_the_elapsed_time`, `saf_req_003_a_gap_longer_than_the_command_period_is_judged_as_that_period`, `saf_req_003_the_default_command_period_is_the_ur5e_extrapolation_bound_plus_one` |
//! | SAF-REQ-005 | TCP speed implied by the command | 1 m/s; 0.25 m/s while C(t) | reduce | `saf_req_005_tcp_speed_limit` |
//! | SAF-REQ-004 | joint acceleration (servoJ: change of implied velocity over the same period, the period by the controller's clock rule `robot_io::cycle_time_s`; speedJ: `acc`) | π rad/s² | reduce (clamp); stop if no scale meets it | `saf_req_004_joint_acceleration_limit`, `saf_req_004_ramp_commanded_every_third_cycle_is_judged_over_the_elapsed_time`, `saf_req_004_a_gap_longer_than_8_cycles_is_judged_as_8`, closed loop: `saf_req_004_a_late_sample_after_a_held_cycle_is_judged_over_the_time_the_plan_advanced` (`tests/tests/closed_loop.rs`) |
//! | SAF-REQ-002 | joint positions of the target and of the stopping configuration | ±2π rad − 0.05 rad margin | stop | `saf_req_002_joint_position_limits` |
//! | SAF-REQ-006 | TCP, wrist and elbow at the target and stopping configuration inside the workspace box | x, y ∈ [−1, 1] m, z ∈ [0.02, 1.3] m | stop | `saf_req_006_workspace_box` |
//! | SAF-REQ-007 | every tracked body part (head sphere, hand points, torso capsule) at least S_p from the surface of every arm capsule (shoulder, upper arm, elbow, forearm, three wrists, gripper, carried part), at the measured joints and at the stopping configuration; the violation names the part and the nearest link | S_p = v_h(T_age + T_r + T_s) + v_r T_r + v_r T_s/2 + C + Z_d + Z_r; v_h 2.0 m/s hands, 1.6 m/s head and torso; C 0.1, Z_d 0.05, Z_r 0.02 m | stop | `saf_req_007_protective_separation`, `saf_req_007_hand_at_each_link_surface_stops_at_rest`, `saf_req_007_hand_at_each_link_surface_stops_in_motion`, `saf_req_007_torso_at_each_link_surface_stops_at_rest`, `saf_req_007_torso_at_each_link_surface_stops_in_motion`, `saf_req_007_default_torso_and_head_radii_count`, `saf_req_007_fault_injection_hand_during_approach` |
//! | SAF-REQ-011 | a latched fault clears only through `reset()`, and only once the cause is gone | — | reset refused | `saf_req_011_latch_clears_only_by_reset_with_cause_gone`, property `saf_req_011_latched_fault_stays_latched` |
//! | SAF-REQ-012 | the robot refuses a command or the link fails while sending | any send error | halt and latch | `saf_req_012_send_failure_latches` |
//!
//! Structural properties, also tested: `step` allocates nothing (`tests/alloc.rs`,
//! `step_allocates_nothing`); a [`SafeCommand`] cannot be built outside the supervisor (the
//! `compile_fail` example on [`SafeCommand`]); no sent command breaks a limit over random
//! commands, states and humans (`tests/properties.rs`,
//! `saf_req_all_no_command_breaks_a_limit`).
//!
//! # Example
//! ```
//! use robot_io::sim::{SimConfig, SimRobot};
//! use robot_io::{JointCommand, RobotState};
//! use safety::{Requirement, Supervisor, SupervisorConfig, Verdict, WorldView};
//!
//! let robot = SimRobot::new(SimConfig::ur5e())?;
//! let mut supervisor = Supervisor::new(robot, SupervisorConfig::ur5e())?;
//! let mut state = RobotState::default();
//! supervisor.read_state(&mut state)?;
//!
//! // A small servo step from the current target passes.
//! let mut q = state.target_q;
//! q[0] += 1e-6;
//! let cmd = JointCommand::Servo { q, lookahead_s: 0.1, gain: 300.0 };
//! assert_eq!(supervisor.step(&cmd, &WorldView::clear(0.0)), Verdict::Passed);
//!
//! // A NaN target is replaced by a stop.
//! q[0] = f64::NAN;
//! let cmd = JointCommand::Servo { q, lookahead_s: 0.1, gain: 300.0 };
//! let verdict = supervisor.step(&cmd, &WorldView::clear(0.002));
//! assert!(verdict.is_stop());
//! assert_eq!(verdict.requirement(), Some(Requirement::Saf001Malformed));
//! assert_eq!(supervisor.counters().fired(Requirement::Saf001Malformed), 1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Limitations
//! - The robot-side control program extrapolates a late servo target along its feed-forward
//!   for at most `extrapolate_max_s` (3 cycles on a robot: ≤ π·0.006 + ½π·0.006² ≈ 0.019 rad
//!   beyond the supervised target; `robot_io::script`). The stopping-configuration check covers
//!   that distance once the fastest joint moves faster than 2·a_stop·0.006 ≈ 0.038 rad/s; below
//!   it the target may pass the checked rest point by at most ≈ 3·10⁻⁴ rad.
//! - SAF-REQ-007's geometry is a model: the capsules cover MuJoCo Menagerie's UR5e collision
//!   geometry with ≥ 14 mm to spare (`robot-io/tests/geometry.rs`), but not the fixed base or
//!   the joint-1 column below the shoulder axis; the gripper and part sizes are configured,
//!   not measured, and the part capsule is always there, carried or not.
//! - The hands are points: the fingers beyond the hand keypoint are the intrusion distance C.
//!   Body parts that are not tracked (`None`), other persons and anything the camera does not
//!   see are not protected by SAF-REQ-007; perception staleness (SAF-REQ-008) bounds how long
//!   tracking may lag.
//! - v_r is the flange's speed (the larger of commanded and measured), not its component
//!   towards each part; a point of the gripper or part can move faster than the flange while
//!   the wrist turns, and elbow and wrist speeds are bounded only through the joint limits.
//! - The workspace box (SAF-REQ-006) still checks the three DH points, not the capsules.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::indexing_slicing))]

mod config;
mod error;
pub mod points;
pub mod separation;
mod supervisor;
mod verdict;

pub use config::{
    CatchUpCycles, CyclePeriod, JointLimits, JointRateLimits, SeparationParams, SpeedLimit,
    SpeedScale, StalenessLimits, SupervisorConfig, WorkspaceBox,
};
pub use error::{Result, SafetyError};
pub use robot_io::geometry::{ArmLink, ArmModel, BodyModel, BodyPart, HumanBody, Torso};
pub use supervisor::{SafeCommand, Supervisor, WorldView};
pub use verdict::{Counters, MalformedInput, Requirement, Verdict, Violation};
