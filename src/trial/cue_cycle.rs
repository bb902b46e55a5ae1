//! The camera-rate cue cycle of a trial: operator cues → assessor → policy → the motion
//! adaptation and the tracked body for the control cycle (`control.rs`).
//!
//! Every operator is an [`OperatorSource`]: the simulated operator, a recorded cue file, or a
//! live camera. [`CueCycle::step`] runs one cue frame through the assessor and the policy,
//! logs the cue-rate streams, and hands back a [`CueOutput`]; the runtime calls it at the cue
//! rate, on the same thread as the control cycle for now (issue 10, deliverable 2: its own
//! thread, behind a single-slot handoff, is still open).

use adapt::controller::MotionAdaptation;
use adapt::task::Phase;
use assess::{AreaRole, Assessor, CueFrame, RobotContext, Workspace};
use policies::{Policy, TaskContext};
use robot_io::geometry::{HumanBody, Torso};

use super::config::FrameConfig;
use super::cues::RecordedCues;
use super::events::TrialEvent;
use super::log::TrialLog;
use super::operator::{RobotView, SimulatedOperator};
use super::runtime::{motion_adaptation, task_phase};

/// Where a trial's operator cues come from: one trait over the simulated operator, a recorded
/// cue file and a live camera.
pub(crate) trait OperatorSource {
    /// What the cues are, for the logs (`None` for the simulated operator).
    fn label(&self) -> Option<&str>;
    /// Whether the operator is simulated (its data is then labelled simulated).
    fn simulated(&self) -> bool;
    /// Fills `frame` for cue time `tc` [s]; returns the time the frame's content is from [s]
    /// (`tc` unless a recorded or camera frame is held), or `None` when the source has ended.
    fn frame(
        &mut self,
        tc: f64,
        robot: &RobotView,
        frame: &mut CueFrame,
        log: &mut TrialLog,
    ) -> crate::Result<Option<f64>>;
    /// The robot released the part to the operator at `t_s` [s].
    fn released(&mut self, _t_s: f64, _log: &mut TrialLog) -> crate::Result<()> {
        Ok(())
    }
    /// Whether the trial's work is done, after `done` of `handovers` handovers.
    fn finished(&self, done: u32, handovers: u32) -> bool {
        done >= handovers
    }
    /// Ends the source (a camera: joins its thread and reports its failure, if any).
    fn finish(self: Box<Self>) -> crate::Result<()> {
        Ok(())
    }
}

impl OperatorSource for SimulatedOperator {
    fn label(&self) -> Option<&str> {
        None
    }
    fn simulated(&self) -> bool {
        true
    }
    fn frame(
        &mut self,
        tc: f64,
        robot: &RobotView,
        frame: &mut CueFrame,
        log: &mut TrialLog,
    ) -> crate::Result<Option<f64>> {
        self.step(tc, robot, frame);
        for e in self.events() {
            log.event(tc, e)?;
        }
        Ok(Some(tc))
    }
    fn released(&mut self, t_s: f64, log: &mut TrialLog) -> crate::Result<()> {
        self.release_confirmed();
        for e in self.events() {
            log.event(t_s, e)?;
        }
        Ok(())
    }
    fn finished(&self, _done: u32, _handovers: u32) -> bool {
        SimulatedOperator::finished(self)
    }
}

impl OperatorSource for RecordedCues {
    fn label(&self) -> Option<&str> {
        Some(RecordedCues::label(self))
    }
    fn simulated(&self) -> bool {
        false
    }
    fn frame(
        &mut self,
        tc: f64,
        _robot: &RobotView,
        frame: &mut CueFrame,
        _log: &mut TrialLog,
    ) -> crate::Result<Option<f64>> {
        Ok(if self.ended(tc) {
            None
        } else {
            Some(self.hold(tc, frame))
        })
    }
}

#[cfg(feature = "vision")]
impl OperatorSource for super::live::LiveCues {
    fn label(&self) -> Option<&str> {
        Some(super::live::LiveCues::label(self))
    }
    fn simulated(&self) -> bool {
        false
    }
    fn frame(
        &mut self,
        tc: f64,
        _robot: &RobotView,
        frame: &mut CueFrame,
        _log: &mut TrialLog,
    ) -> crate::Result<Option<f64>> {
        Ok(self.hold(tc, frame))
    }
    fn finish(self: Box<Self>) -> crate::Result<()> {
        super::live::LiveCues::finish(*self)
    }
}

/// What one cue cycle hands the control cycle (and the progress display).
#[derive(Debug, Clone, Copy)]
pub(crate) struct CueOutput {
    /// The operator's tracked body, robot base frame.
    pub(crate) humans: HumanBody,
    /// The policy's adaptation, mapped for the controller (fails closed).
    pub(crate) motion: MotionAdaptation,
    /// The time the frame's content is from [s] (its age is the perception age).
    pub(crate) cue_t_s: f64,
    /// Windowed HRC-CWL [-] and the dominant indicator's key, for the progress display.
    pub(crate) hrc_cwl: f64,
    pub(crate) dominant: &'static str,
}

/// Operator source → assessor → policy; see the [module docs](self).
pub(crate) struct CueCycle {
    pub(crate) source: Box<dyn OperatorSource>,
    assessor: Assessor,
    policy: Box<dyn Policy + Send>,
    workspace: Workspace,
    frame_cfg: FrameConfig,
    frame: CueFrame,
    assembly_since: Option<f64>,
    last_indicator: Option<Option<assess::Indicator>>,
}

impl CueCycle {
    pub(crate) fn new(
        source: Box<dyn OperatorSource>,
        assessor: Assessor,
        policy: Box<dyn Policy + Send>,
        workspace: Workspace,
        frame_cfg: FrameConfig,
    ) -> Self {
        Self {
            source,
            assessor,
            policy,
            workspace,
            frame_cfg,
            frame: CueFrame::empty(0.0),
            assembly_since: None,
            last_indicator: None,
        }
    }

    /// Ends the operator source (see [`OperatorSource::finish`]).
    pub(crate) fn finish(self) -> crate::Result<()> {
        self.source.finish()
    }

    /// One cue frame at cue time `tc` [s], seen with the robot as `view` / `robot` in task
    /// phase `phase`; `None` when the operator source has ended.
    pub(crate) fn step(
        &mut self,
        tc: f64,
        view: &RobotView,
        robot: RobotContext,
        phase: Phase,
        log: &mut TrialLog,
    ) -> crate::Result<Option<CueOutput>> {
        let Some(cue_t) = self.source.frame(tc, view, &mut self.frame, log)? else {
            return Ok(None);
        };
        let frame = &mut self.frame;
        frame.robot = robot;
        log.cues(tc, frame)?;
        let a = self.assessor.update(frame);
        log.assessment(tc, a, &self.workspace)?;
        let confirmed_role = a.confirmed.and_then(|id| self.workspace.role(id));
        if confirmed_role == Some(AreaRole::Assembly) {
            self.assembly_since.get_or_insert(tc);
        } else {
            self.assembly_since = None;
        }
        let ctx = TaskContext {
            now_s: tc,
            phase: task_phase(phase),
            in_collaboration_area: confirmed_role == Some(AreaRole::Collaboration),
            in_instruction_area: confirmed_role == Some(AreaRole::Instruction),
            assembly_dwell_s: self.assembly_since.map_or(0.0, |s| tc - s),
        };
        let adaptation = self.policy.decide(a, &ctx);
        log.adaptation(tc, &adaptation)?;
        if self.last_indicator != Some(adaptation.reason.indicator) {
            if self.last_indicator.is_some() {
                log.event(
                    tc,
                    &TrialEvent::AdaptationChanged {
                        indicator: policies::indicator_key(adaptation.reason.indicator),
                    },
                )?;
            }
            self.last_indicator = Some(adaptation.reason.indicator);
        }
        // Human points in the base frame (head, hands, torso).
        let tf = &self.frame_cfg;
        let to_base = |p: &assess::Vec3| tf.to_base([p.x, p.y, p.z]);
        let humans = HumanBody {
            head_m: frame.head.as_ref().map(|h| to_base(&h.position)),
            left_hand_m: frame.hands[0].as_ref().map(|h| to_base(&h.position)),
            right_hand_m: frame.hands[1].as_ref().map(|h| to_base(&h.position)),
            torso: frame.body.as_ref().map(|b| Torso {
                shoulder_mid_m: to_base(&b.position),
                normal: tf.direction_to_base([b.facing.x, b.facing.y, b.facing.z]),
            }),
        };
        Ok(Some(CueOutput {
            humans,
            motion: motion_adaptation(&adaptation),
            cue_t_s: cue_t,
            hrc_cwl: a.windowed.hrc_cwl,
            dominant: policies::indicator_key(a.dominant.indicator),
        }))
    }
}
