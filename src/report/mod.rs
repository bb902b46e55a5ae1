//! Outputs of `hrc-adapt assess`: the per-frame indicator table and the indicator-dynamics plots.

pub(crate) mod plot;
pub(crate) mod table;

/// What the plots need of one assessed frame (the cumulative indicators and the context flags).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Sample {
    /// Frame time t [s].
    pub(crate) t: f64,
    /// Cumulative AED, TID, ICD [-].
    pub(crate) demand: [f64; 3],
    /// Cumulative ASD_ctx [weighted switches / s].
    pub(crate) asd_ctx: f64,
    /// Cumulative OHD [-].
    pub(crate) ohd: f64,
    /// Cumulative HRC-CWL [-].
    pub(crate) hrc_cwl: f64,
    /// Windowed HRC-CWL [-].
    pub(crate) hrc_cwl_windowed: f64,
    /// C(t): a robot-collaboration period is active.
    pub(crate) collaborating: bool,
    /// H(t): the frame counts as hesitation.
    pub(crate) hesitating: bool,
}

impl Sample {
    /// The plotted values of an assessment.
    pub(crate) fn of(a: &assess::Assessment) -> Self {
        let c = &a.cumulative;
        Self {
            t: a.t,
            demand: [c.aed, c.tid, c.icd],
            asd_ctx: c.asd_ctx,
            ohd: c.ohd,
            hrc_cwl: c.hrc_cwl,
            hrc_cwl_windowed: a.windowed.hrc_cwl,
            collaborating: a.collaborating,
            hesitating: a.hesitating,
        }
    }
}
