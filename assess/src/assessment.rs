//! The assessor's output per frame.

use crate::area::AreaId;
use crate::cue::Hand;

/// One of the five components of HRC-CWL, in component order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Indicator {
    /// Assembly execution demand, D_ass.
    Aed = 0,
    /// Tool identification demand, D_id.
    Tid = 1,
    /// Instruction checking demand, D_ins.
    Icd = 2,
    /// Context-aware attention switching demand (as ASD̃ in the composite).
    AsdCtx = 3,
    /// Operation hesitation demand.
    Ohd = 4,
}

impl Indicator {
    /// All five, in component order (the tie-break order of the dominant indicator).
    pub const ALL: [Indicator; 5] = [
        Indicator::Aed,
        Indicator::Tid,
        Indicator::Icd,
        Indicator::AsdCtx,
        Indicator::Ohd,
    ];

    /// Name as in the paper: `AED`, `TID`, `ICD`, `ASD_ctx`, `OHD`.
    pub fn name(self) -> &'static str {
        match self {
            Indicator::Aed => "AED",
            Indicator::Tid => "TID",
            Indicator::Icd => "ICD",
            Indicator::AsdCtx => "ASD_ctx",
            Indicator::Ohd => "OHD",
        }
    }

    /// From its component index 0..5.
    pub fn from_index(i: usize) -> Option<Self> {
        Self::ALL.get(i).copied()
    }
}

/// HRC-CWL category.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub enum Category {
    /// HRC-CWL < medium_from.
    #[default]
    Low,
    /// medium_from ≤ HRC-CWL < high_from.
    Medium,
    /// HRC-CWL ≥ high_from.
    High,
}

impl Category {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Category::Low => "low",
            Category::Medium => "medium",
            Category::High => "high",
        }
    }
}

/// The indicators, either cumulative from the first frame or over the sliding window.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Indicators {
    /// AED = D_ass [-] in [0, 1].
    pub aed: f64,
    /// TID = D_id [-] in [0, 1].
    pub tid: f64,
    /// ICD = D_ins [-] in [0, 1].
    pub icd: f64,
    /// COL = D_col [-] in [0, 1] (diagnostic).
    pub col: f64,
    /// ABI [-] in [0, 1] (diagnostic).
    pub abi: f64,
    /// ASD_ctx [weighted switches / s], ≥ 0.
    pub asd_ctx: f64,
    /// ASD̃ = min(1, ASD_ctx / ASD_ref) [-] in [0, 1].
    pub asd_norm: f64,
    /// OHD [-] in [0, 1].
    pub ohd: f64,
    /// HRC-CWL = wᵀx̃ [-] in [0, 1].
    pub hrc_cwl: f64,
    /// Category of `hrc_cwl`.
    pub category: Category,
    /// T_v: valid observation time [s].
    pub valid_time_s: f64,
    /// Σ costs of the switch events [-].
    pub switch_cost: f64,
    /// T_hes: hesitation time [s].
    pub hesitation_time_s: f64,
    /// T_collab: collaboration time [s].
    pub collaboration_time_s: f64,
    /// ∫ v_AB: time both ABI sub-states were valid [s].
    pub ab_valid_time_s: f64,
    /// ∫ I_AB: inconsistent time [s].
    pub ab_inconsistent_time_s: f64,
}

impl Indicators {
    /// The normalised component vector x̃ = (AED, TID, ICD, ASD̃, OHD).
    pub fn components(&self) -> [f64; 5] {
        [self.aed, self.tid, self.icd, self.asd_norm, self.ohd]
    }

    /// The value of one component of x̃.
    pub fn component(&self, k: Indicator) -> f64 {
        self.components()[k as usize]
    }
}

/// The dominant indicator as streamed to the policy layer.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Dominant {
    /// The reported dominant indicator; `None` means "none".
    pub indicator: Option<Indicator>,
    /// Its current contribution e_k = w_k · max(0, x̃_k − b_k) [-]; 0 for "none".
    pub strength: f64,
    /// How long the reported value has held [s].
    pub held_for_s: f64,
    /// The current candidate (argmax e_k, or "none").
    pub candidate: Option<Indicator>,
    /// e_k of every component on this frame [-].
    pub contributions: [f64; 5],
    /// The baseline b in use, once known.
    pub baseline: Option<[f64; 5]>,
    /// True while the baseline is still being calibrated (no dominant is reported then).
    pub calibrating: bool,
}

/// Everything the assessor knows after a frame.
///
/// Area states are `Option<AreaId>`: `None` is the unassigned state ∅.
#[derive(Debug, Clone, PartialEq)]
pub struct Assessment {
    /// The frame time t [s].
    pub t: f64,
    /// Frames accepted so far.
    pub frames: u64,
    /// Frames rejected so far because their time was not finite or did not increase.
    pub rejected_frames: u64,
    /// Whether the last frame given to `update` was rejected (then nothing else changed).
    pub last_rejected: bool,
    /// Δt_k this frame contributed to the integrals (capped at Δt_max) [s].
    pub dt_s: f64,
    /// v_F: at least one cue was present.
    pub valid: bool,
    /// Which cues were present (head, body, hand).
    pub present: [bool; 3],
    /// A large upper-body reorientation switched the fusion to the turn weights.
    pub turning: bool,
    /// The fusion weights used (head, body, hand), after confidence and renormalisation [-].
    pub weights: [f64; 3],
    /// F_raw: the frame's raw state.
    pub raw: Option<AreaId>,
    /// The fused score S_i* of the raw argmax [-].
    pub raw_score: f64,
    /// F: the confirmed state.
    pub confirmed: Option<AreaId>,
    /// F^per: the perceptual (head + body) confirmed state, and whether it was valid on this frame.
    pub perceptual: (Option<AreaId>, bool),
    /// F^act: the action (hand) confirmed state, and whether it was valid on this frame.
    pub action: (Option<AreaId>, bool),
    /// The active hand, if a hand was present.
    pub active_hand: Option<Hand>,
    /// v_h: filtered speed of the active hand, when defined [m/s].
    pub hand_speed_m_s: Option<f64>,
    /// v_th: the low-motion threshold in force [m/s].
    pub speed_threshold_m_s: f64,
    /// The frame satisfies C ∧ G ∧ v_h < v_th (a low-motion run continues or starts).
    pub low_motion: bool,
    /// The current low-motion run has reached t_min, so this frame counts as hesitation (H = 1).
    pub hesitating: bool,
    /// The robot context of the frame.
    pub collaborating: bool,
    /// A switch event happened on this frame, with its cost [-].
    pub switch_cost: Option<f64>,
    /// Switch events so far.
    pub switches: u64,
    /// Indicators cumulative from the first frame (the paper's output).
    pub cumulative: Indicators,
    /// Indicators over the sliding window H (for adaptation).
    pub windowed: Indicators,
    /// Cumulative D_i of every area, in calibration order [-].
    pub area_demand: Vec<f64>,
    /// Windowed D_i of every area [-].
    pub area_demand_windowed: Vec<f64>,
    /// The dominant indicator (from the windowed values).
    pub dominant: Dominant,
    /// The window ring was full, so some frames left the window early (frame rate above
    /// `window.max_rate_hz`).
    pub window_overflow: bool,
}
