//! Trial events shared by the runtime (which emits them) and the log (which records them and
//! builds the summary from them).

/// What happened during a trial, beyond the sampled streams. Times are trial time [s].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum TrialEvent {
    /// The handover task entered a phase (the name of `adapt::task::Phase`, e.g. "Approach").
    TaskPhase { phase: &'static str },
    /// The robot is presenting the part at the handover pose (it starts waiting for the grasp).
    Presented { handover: u32 },
    /// The operator grasped the part; the handover is complete from the operator's side.
    Grasped { handover: u32 },
    /// The robot gave up presenting and returned the part (timeout).
    PartReturned { handover: u32 },
    /// The (simulated) operator needs the next part and starts waiting for it.
    OperatorNeedsPart { handover: u32 },
    /// The operator becomes idle (true) or busy again (false).
    OperatorIdle { idle: bool },
    /// The operator starts (true) or ends (false) a hesitation episode (simulated ground truth).
    Hesitation { active: bool },
    /// The policy changed its adaptation (the rule's indicator, or "none").
    AdaptationChanged { indicator: &'static str },
    /// The safety supervisor did not pass commands unchanged: a (reaction, requirement) pair that
    /// held for the debounce time (see the `log` module docs, "Safety events"); stamped with
    /// its onset.
    Safety {
        /// "reduced", "stopped" or "halted".
        reaction: &'static str,
        /// The requirement that fired, e.g. "SAF-REQ-007".
        requirement: &'static str,
    },
    /// The robot link was lost (`up: false`: no robot state for `[link] lost_after_s`; the
    /// trial pauses) or is back and the trial resumes (`up: true`).
    Link { up: bool },
    /// The trial ended (all handovers done, stopped by the user, or a fault).
    Finished { reason: &'static str },
}
