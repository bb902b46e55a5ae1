//! Per-frame cues: the model's input ([`spec`](crate::spec), "Inputs per frame").

use crate::Vec3;

/// Head cue q_h: where the head is and where it faces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadCue {
    /// Head position x_h in the workspace frame [m].
    pub position: Vec3,
    /// Facing direction o_h in the workspace frame (any length > 0; normalised internally) [-].
    pub facing: Vec3,
    /// Confidence in [0, 1] [-].
    pub confidence: f64,
}

/// Upper-body cue q_b: shoulder midpoint and torso normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyCue {
    /// Shoulder midpoint x_b in the workspace frame [m].
    pub position: Vec3,
    /// Torso normal o_b in the workspace frame (any length > 0; normalised internally) [-].
    pub facing: Vec3,
    /// Confidence in [0, 1] [-].
    pub confidence: f64,
}

/// Hand cue q_m: one hand's position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandCue {
    /// Hand position x_m in the workspace frame [m].
    pub position: Vec3,
    /// Confidence in [0, 1] [-].
    pub confidence: f64,
}

/// Which hand a [`HandCue`] belongs to; the index into [`CueFrame::hands`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Hand {
    /// The operator's left hand (`hands[0]`).
    Left = 0,
    /// The operator's right hand (`hands[1]`).
    Right = 1,
}

impl Hand {
    /// Both hands, in index order.
    pub const BOTH: [Hand; 2] = [Hand::Left, Hand::Right];

    /// Lower-case name, as written in logs.
    pub fn name(self) -> &'static str {
        match self {
            Hand::Left => "left",
            Hand::Right => "right",
        }
    }
}

/// Robot context of a frame, from the robot side of the trial ([`spec`](crate::spec), "Robot
/// context").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RobotContext {
    /// C(t): a robot-collaboration period is active (approaching, presenting or waiting at the handover).
    pub collaborating: bool,
    /// G(t): the current collaborative operation is incomplete.
    pub incomplete: bool,
}

/// Everything the assessor is given for one frame.
///
/// Missing cues are `None`. A cue with a non-finite value, a zero-length facing vector or a
/// confidence below `fusion.min_confidence` is treated as missing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CueFrame {
    /// Frame time t [s]; must increase from frame to frame (a frame whose t does not is rejected).
    pub t: f64,
    /// Head cue.
    pub head: Option<HeadCue>,
    /// Upper-body cue.
    pub body: Option<BodyCue>,
    /// Hand cues, indexed by [`Hand`]: `[left, right]`. The assessor picks the active hand.
    pub hands: [Option<HandCue>; 2],
    /// Robot context C(t), G(t).
    pub robot: RobotContext,
}

impl CueFrame {
    /// A frame at time `t` [s] with no cue and no collaboration.
    pub fn empty(t: f64) -> Self {
        Self {
            t,
            head: None,
            body: None,
            hands: [None, None],
            robot: RobotContext::default(),
        }
    }

    /// The cue of one hand.
    pub fn hand(&self, hand: Hand) -> Option<&HandCue> {
        self.hands[hand as usize].as_ref()
    }
}
