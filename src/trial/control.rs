//! The 500 Hz control cycle of a trial: (the caller reads the state) → controller → supervisor
//! → send → log ring. [`ControlCycle::act`] is the part after the read; with
//! [`ControlCycle::read`] it is the whole cycle the runtime runs each 2 ms, on the mock clock
//! and on an RTDE robot alike.
//!
//! Real-time contract: neither call allocates (the log calls copy `Copy` records into the
//! trial log's preallocated ring; the controller, the supervisor and the RTDE client keep
//! their buffers). The tests in `src/trial/control_tests.rs`
//! (`the_control_cycle_allocates_nothing_on_the_simulated_robot`,
//! `the_control_cycle_allocates_nothing_over_rtde_to_the_emulator`) prove it with a counting
//! allocator over whole handovers, the runtime's per-cycle handover scheduling included.
//! Waiting: `read` on the simulated robot never waits; on RTDE (`backend::PacedRtde`) it polls
//! for the next controller sample for at most one controller period (2 ms), waiting for no
//! other thread (`backend::paced_read` and its tests). The supervisor's send is the RTDE
//! client's register write, which takes no lock the client's tasks hold.
//!
//! On an RTDE robot the cycle runs on its own thread and logs into a [`super::log::ControlLog`]
//! (see the runtime's module docs); on the mock clock it logs straight into the trial log.

use adapt::controller::{Controller, MotionAdaptation, OperatorView};
use adapt::task::{Phase, TaskEventKind};
use robot_io::geometry::{ARM_CAPSULES, Capsule, HumanBody, closest_approaches};
use robot_io::{JointCommand, RobotState};
use safety::{Supervisor, SupervisorConfig, Verdict, WorldView};

use super::events::TrialEvent;
use super::log::{ControlSink, CycleRecord};
use super::runtime::{TrialRobot, phase_name};

/// How long a supervisor verdict (reaction, requirement) must hold before it is logged as a
/// safety event [s] (see the `log` module docs, "Safety events").
pub(crate) const SAFETY_DEBOUNCE_S: f64 = 0.05;

/// What the cycle needs from the rest of the trial, besides the robot state.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CycleInput<'a> {
    /// Trial time of this cycle [s].
    pub(crate) t_s: f64,
    /// Whether this cycle's state is a new robot sample (not the held one).
    pub(crate) fresh: bool,
    /// The operator's tracked body, base frame.
    pub(crate) humans: HumanBody,
    /// Trial time of the cue frame `humans` comes from [s].
    pub(crate) cue_t_s: f64,
    /// The policy's current adaptation.
    pub(crate) motion: &'a MotionAdaptation,
    /// Handovers armed and completed so far (for event numbers).
    pub(crate) started: u32,
    pub(crate) done: u32,
    /// Whether the operator is simulated (the caller then tells it about a release).
    pub(crate) simulated: bool,
    /// Control cycles skipped before this one (0 on the mock clock).
    pub(crate) missed: u32,
    /// When this cycle's state was read (real time only): the cycle record's latency is the
    /// wall time from it to the send.
    pub(crate) read_at: Option<std::time::Instant>,
    /// Wake jitter [s] (real time only).
    pub(crate) wake_jitter_s: Option<f64>,
}

/// What one cycle did that the rest of the trial acts on.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CycleOutput {
    /// The supervisor's verdict on this cycle's command.
    pub(crate) verdict: Verdict,
    /// The operator took the part this cycle (the controller confirmed the release).
    pub(crate) released: bool,
}

/// The controller, the supervisor (and through it the robot) and what the 500 Hz cycle keeps
/// between cycles; see the [module docs](self).
pub(crate) struct ControlCycle<R: TrialRobot> {
    pub(crate) supervisor: Supervisor<R>,
    pub(crate) controller: Controller,
    /// The latest robot state (held when a cycle brings no new sample).
    pub(crate) state: RobotState,
    /// The supervisor's view of the world (the exit path uses it to stop the robot).
    pub(crate) world: WorldView,
    cmd: JointCommand,
    safety_events: SafetyDebounce,
    capsules: [Capsule; ARM_CAPSULES],
}

impl<R: TrialRobot> ControlCycle<R> {
    pub(crate) fn new(supervisor: Supervisor<R>, controller: Controller) -> Self {
        Self {
            supervisor,
            controller,
            state: RobotState::default(),
            world: WorldView::clear(0.0),
            cmd: JointCommand::Stop { decel: 3.0 },
            safety_events: SafetyDebounce::new(SAFETY_DEBOUNCE_S),
            capsules: [Capsule::point([0.0; 3], 0.0); ARM_CAPSULES],
        }
    }

    /// Reads the newest robot state into [`ControlCycle::state`] through the supervisor.
    /// `Ok(false)`: no new sample (the state is held; the supervisor counts the missed cycle,
    /// SAF-REQ-009), because the link is down or none is due yet.
    pub(crate) fn read(&mut self, last_ts: f64) -> Result<bool, safety::SafetyError> {
        match self.supervisor.read_state(&mut self.state) {
            Ok(()) => Ok(self.state.timestamp_s > last_ts),
            Err(safety::SafetyError::Robot(e)) if is_link_error(&e) => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// Controller → supervisor → send → log ring, for the state read last.
    pub(crate) fn act<L: ControlSink>(
        &mut self,
        input: &CycleInput<'_>,
        log: &mut L,
    ) -> crate::Result<CycleOutput> {
        let t = input.t_s;
        let perception_age_s = (t - input.cue_t_s).max(0.0);
        let view = OperatorView {
            body: input.humans,
            perception_age_s,
        };
        self.controller
            .step(t, &self.state, input.motion, &view, &mut self.cmd);
        let mut released = false;
        for ev in self.controller.events() {
            match ev.kind {
                TaskEventKind::PhaseChanged { to, .. } => {
                    log.event(
                        t,
                        &TrialEvent::TaskPhase {
                            phase: phase_name(to),
                        },
                    )?;
                    if to == Phase::Present {
                        log.event(
                            t,
                            &TrialEvent::Presented {
                                handover: input.started,
                            },
                        )?;
                    }
                }
                TaskEventKind::PresentTimeout => log.event(
                    t,
                    &TrialEvent::PartReturned {
                        handover: input.started,
                    },
                )?,
                TaskEventKind::ReleaseConfirmed => {
                    if !input.simulated {
                        log.event(
                            t,
                            &TrialEvent::Grasped {
                                handover: input.done + 1,
                            },
                        )?;
                    }
                    released = true;
                }
                TaskEventKind::PartGripped | TaskEventKind::GraspDetected { .. } => {}
            }
        }
        self.world.now_s = t;
        // The supervisor watches the same tracked body as the planner, torso included.
        self.world.human = input.humans;
        self.world.perception_age_s = perception_age_s;
        self.world.collaborating = self.controller.collaborating();
        let verdict = self.supervisor.step(&self.cmd, &self.world);
        // A command the supervisor changed was not executed as planned: the controller
        // re-plans from the robot's state (a change by rounding alone does not count); after a
        // stop it first lets the robot come to rest.
        match &verdict {
            Verdict::Passed => {}
            Verdict::Reduced { scale, .. } => {
                // Slowed for a cap (< 1) or, for a too-hard deceleration, slowed at the
                // acceleration limit (> 1): either way not the planned motion.
                if (*scale - 1.0).abs() > 1e-6 {
                    self.controller.command_reduced(*scale);
                }
            }
            Verdict::Stopped { .. } | Verdict::Halted { .. } => {
                self.controller.command_overridden()
            }
        }
        let pair = (
            verdict_kind(&verdict),
            verdict.requirement().map_or("none", |r| r.id()),
        );
        if let Some((onset, (reaction, requirement))) = self.safety_events.update(t, pair) {
            log.event(
                onset,
                &TrialEvent::Safety {
                    reaction,
                    requirement,
                },
            )?;
        }
        if input.fresh {
            // A held state is no new robot sample: robot.csv keeps the robot's own.
            log.robot_state(t, &self.state)?;
        }
        log.command(t, &self.cmd, &verdict)?;
        // Read → send: the supervisor's step above sent the command.
        let latency_s = input.read_at.map(|at| at.elapsed().as_secs_f64());
        log.cycle(
            t,
            &CycleRecord {
                missed: input.missed,
                latency_s,
                wake_jitter_s: input.wake_jitter_s,
                jerk_limit_rad_s3: self.controller.jerk_limit_rad_s3(),
                time_scale: self.controller.scale_report().scale,
            },
        )?;
        log.human_distance(
            t,
            min_human_distance_m(
                &input.humans,
                &self.state.actual_q,
                self.supervisor.config(),
                &mut self.capsules,
            ),
        )?;
        Ok(CycleOutput { verdict, released })
    }
}

/// A robot-io error that means "no new sample now" rather than a failure of the loop: the
/// link is down or being re-established.
pub(crate) fn is_link_error(e: &robot_io::RobotIoError) -> bool {
    matches!(
        e,
        robot_io::RobotIoError::LinkDown { .. }
            | robot_io::RobotIoError::LinkClosed { .. }
            | robot_io::RobotIoError::Timeout { .. }
    )
}

/// Turns the per-cycle supervisor verdicts into safety events: an event is emitted when the
/// (reaction, requirement) pair changes to a non-`passed` pair **and** the new pair has held
/// for `hold_s`; it is stamped with the time the pair started. A return to `passed` that holds
/// for `hold_s` re-arms it (no event). Shorter excursions are not events; every verdict is still
/// in `/robot/command`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SafetyDebounce {
    hold_s: f64,
    logged: (&'static str, &'static str),
    candidate: (&'static str, &'static str),
    since_s: f64,
}

impl SafetyDebounce {
    const PASSED: (&'static str, &'static str) = ("passed", "none");

    pub(crate) fn new(hold_s: f64) -> Self {
        Self {
            hold_s,
            logged: Self::PASSED,
            candidate: Self::PASSED,
            since_s: 0.0,
        }
    }

    /// Feeds the verdict of the cycle at `t_s`; returns (onset [s], pair) of a new event.
    pub(crate) fn update(
        &mut self,
        t_s: f64,
        pair: (&'static str, &'static str),
    ) -> Option<(f64, (&'static str, &'static str))> {
        if pair != self.candidate {
            self.candidate = pair;
            self.since_s = t_s;
        }
        if self.candidate != self.logged && t_s - self.since_s >= self.hold_s - 1e-9 {
            self.logged = self.candidate;
            if self.logged != Self::PASSED {
                return Some((self.since_s, self.logged));
            }
        }
        None
    }
}

fn verdict_kind(v: &Verdict) -> &'static str {
    match v {
        Verdict::Passed => "passed",
        Verdict::Reduced { .. } => "reduced",
        Verdict::Stopped { .. } => "stopped",
        Verdict::Halted { .. } => "halted",
    }
}

/// The smallest surface distance between the operator's tracked body (head, hands, torso;
/// base frame) and the arm's capsules at the measured joints `q` [rad], with the supervisor's
/// arm and body models [m]; `None` when nothing is tracked. `capsules` is scratch space.
fn min_human_distance_m(
    humans: &HumanBody,
    q: &robot_io::Joints,
    cfg: &SupervisorConfig,
    capsules: &mut [Capsule; ARM_CAPSULES],
) -> Option<f64> {
    cfg.arm.capsules(q, capsules);
    closest_approaches(capsules, humans, &cfg.body)
        .iter()
        .flatten()
        .map(|a| a.distance_m)
        .reduce(f64::min)
}
