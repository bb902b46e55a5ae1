//! Model parameters (every constant of the [`spec`](crate::spec)), with its defaults, loaded from
//! TOML and validated.
//!
//! Every key is optional; an absent key keeps its default. Unknown keys are rejected.
//! `AssessConfig::default()` is the spec's configuration. `config/assess.toml` lists every key.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{AssessError, Result};

/// Cue weights (ω_h, ω_b, ω_m) of the fusion, summing to 1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CueWeights {
    /// Head weight ω_h [-].
    pub head: f64,
    /// Upper-body weight ω_b [-].
    pub body: f64,
    /// Hand weight ω_m [-].
    pub hand: f64,
}

/// §1–2: evidence and fusion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FusionConfig {
    /// Nominal base weights; default (0.6, 0.25, 0.15).
    pub weights: CueWeights,
    /// Base weights during a large upper-body reorientation; default (0.3, 0.55, 0.15).
    pub turn_weights: CueWeights,
    /// c_min: a cue is present when its confidence is at least this [-]; default 0.3.
    pub min_confidence: f64,
    /// Torso yaw rate above which a reorientation is large [deg/s]; default 90.
    pub turn_yaw_rate_deg_s: f64,
    /// The yaw rate compares the current frame with the frame this many valid body frames
    /// earlier, in [1, [`MAX_FRAMES`]]; default 3.
    pub turn_lookback_frames: usize,
    /// τ: the fused score a raw state needs [-], in (0, 1]; default 0.7.
    pub tau: f64,
}

impl Default for FusionConfig {
    fn default() -> Self {
        Self {
            weights: CueWeights {
                head: 0.6,
                body: 0.25,
                hand: 0.15,
            },
            turn_weights: CueWeights {
                head: 0.3,
                body: 0.55,
                hand: 0.15,
            },
            min_confidence: 0.3,
            turn_yaw_rate_deg_s: 90.0,
            turn_lookback_frames: 3,
            tau: 0.7,
        }
    }
}

/// §3: temporal confirmation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ConfirmationConfig {
    /// M: the window of valid frames [frames], in [1, [`MAX_FRAMES`]]; default 15 (0.5 s at
    /// 30 fps). γ is a strict majority.
    pub window_frames: usize,
}

impl Default for ConfirmationConfig {
    fn default() -> Self {
        Self { window_frames: 15 }
    }
}

/// §4–5: integration of demand, and the action state of ABI.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DemandConfig {
    /// Δt_max: a frame interval is capped here; the rest is invalid time [s]; default 0.2.
    pub max_frame_interval_s: f64,
    /// d_act: the action state takes the nearest area within this distance [m]; default 0.10.
    pub action_radius_m: f64,
}

impl Default for DemandConfig {
    fn default() -> Self {
        Self {
            max_frame_interval_s: 0.2,
            action_radius_m: 0.10,
        }
    }
}

/// §6: switching costs, c_high > c_int > c_base > 0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SwitchingConfig {
    /// c_high, for {instruction, assembly} [-]; default 3.
    pub cost_high: f64,
    /// c_int, for {collaboration, tool identification} [-]; default 2.
    pub cost_int: f64,
    /// c_base, for every other pair of areas [-]; default 1.
    pub cost_base: f64,
}

impl Default for SwitchingConfig {
    fn default() -> Self {
        Self {
            cost_high: 3.0,
            cost_int: 2.0,
            cost_base: 1.0,
        }
    }
}

/// One-Euro filter parameters (Casiez et al., CHI 2012).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OneEuroConfig {
    /// Minimum cutoff frequency [Hz]; default 1.0.
    pub min_cutoff_hz: f64,
    /// Speed coefficient β [s/m]; default 0.05.
    pub beta: f64,
    /// Cutoff of the derivative filter [Hz]; default 1.0.
    pub d_cutoff_hz: f64,
}

impl Default for OneEuroConfig {
    fn default() -> Self {
        Self {
            min_cutoff_hz: 1.0,
            beta: 0.05,
            d_cutoff_hz: 1.0,
        }
    }
}

/// §7: operation hesitation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HesitationConfig {
    /// The hand-position filter.
    pub one_euro: OneEuroConfig,
    /// k_v: v_th = clamp(k_v · median, v_min, v_max) [-]; default 0.35.
    pub k_v: f64,
    /// v_min [m/s]; default 0.03.
    pub v_min_m_s: f64,
    /// v_max [m/s]; default 0.10.
    pub v_max_m_s: f64,
    /// The median covers samples of the last this many seconds [s]; default 10.
    /// `median_horizon_s × window.max_rate_hz` must stay ≤ 1e7 samples (its buffer).
    pub median_horizon_s: f64,
    /// Until the samples' Δt add up to this, v_th = v_max [s]; default 1.
    pub min_sample_time_s: f64,
    /// t_min: a low-motion run counts once it lasts this long [s]; default 0.3.
    pub min_duration_s: f64,
    /// ε in OHD = T_hes / (T_collab + ε) [s]; default 1e-3.
    pub epsilon_s: f64,
}

impl Default for HesitationConfig {
    fn default() -> Self {
        Self {
            one_euro: OneEuroConfig::default(),
            k_v: 0.35,
            v_min_m_s: 0.03,
            v_max_m_s: 0.10,
            median_horizon_s: 10.0,
            min_sample_time_s: 1.0,
            min_duration_s: 0.3,
            epsilon_s: 1e-3,
        }
    }
}

/// Per-component values over (AED, TID, ICD, ASD̃, OHD).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ComponentValues {
    /// AED.
    pub aed: f64,
    /// TID.
    pub tid: f64,
    /// ICD.
    pub icd: f64,
    /// ASD̃ (normalised switching demand).
    pub asd: f64,
    /// OHD.
    pub ohd: f64,
}

impl ComponentValues {
    /// As an array in component order (AED, TID, ICD, ASD, OHD).
    pub fn to_array(self) -> [f64; 5] {
        [self.aed, self.tid, self.icd, self.asd, self.ohd]
    }

    /// From an array in component order.
    pub fn from_array(a: [f64; 5]) -> Self {
        Self {
            aed: a[0],
            tid: a[1],
            icd: a[2],
            asd: a[3],
            ohd: a[4],
        }
    }
}

/// §8: the composite HRC-CWL and its category.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CompositeConfig {
    /// w ≥ 0 with Σw = 1 (tolerance 1e-9); default uniform 0.2.
    pub weights: ComponentValues,
    /// ASD_ref: ASD̃ = min(1, ASD_ctx / ASD_ref) [1/s]; default 0.5.
    pub asd_ref_per_s: f64,
    /// HRC-CWL at or above this is `medium` [-]; default 0.33.
    pub medium_from: f64,
    /// HRC-CWL at or above this is `high` [-]; default 0.66.
    pub high_from: f64,
}

impl Default for CompositeConfig {
    fn default() -> Self {
        Self {
            weights: ComponentValues::from_array([0.2; 5]),
            asd_ref_per_s: 0.5,
            medium_from: 0.33,
            high_from: 0.66,
        }
    }
}

/// §8: the sliding horizon of the windowed indicators.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WindowConfig {
    /// H: frames with t_now − t_k < H belong to the window [s]; default 30.
    pub horizon_s: f64,
    /// The highest frame rate the window is sized for [Hz]; default 240. Above it, the oldest
    /// frames leave the window early and the assessment flags `window_overflow`.
    pub max_rate_hz: f64,
}

impl Default for WindowConfig {
    fn default() -> Self {
        Self {
            horizon_s: 30.0,
            max_rate_hz: 240.0,
        }
    }
}

/// Where the dominant indicator's baseline b comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BaselineMode {
    /// Averaged over the valid frames of the first `calibration_s` seconds; no dominant indicator
    /// is reported before. If that period has no valid frame, `baseline` is used.
    Calibrate,
    /// `baseline` from the config, used from the first frame.
    Fixed,
}

/// §8: the dominant indicator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DominantConfig {
    /// Baseline source; default `calibrate`.
    pub baseline_mode: BaselineMode,
    /// The calibration period from the first frame [s]; default 60.
    pub calibration_s: f64,
    /// The fixed baseline b; default (0.50, 0.15, 0.15, 0.20, 0.10).
    pub baseline: ComponentValues,
    /// Every e_k at or below this → the candidate is "none" [-]; default 0.01.
    pub none_threshold: f64,
    /// T_dom: a candidate must hold this long without a break [s]; default 3.
    pub hold_s: f64,
    /// The lead over the current dominant's e a new indicator needs [-]; default 0.02.
    pub margin: f64,
}

impl Default for DominantConfig {
    fn default() -> Self {
        Self {
            baseline_mode: BaselineMode::Calibrate,
            calibration_s: 60.0,
            baseline: ComponentValues::from_array([0.50, 0.15, 0.15, 0.20, 0.10]),
            none_threshold: 0.01,
            hold_s: 3.0,
            margin: 0.02,
        }
    }
}

/// All parameters of the assessment model. `Default` is the [`spec`](crate::spec)'s values.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AssessConfig {
    /// §1–2.
    pub fusion: FusionConfig,
    /// §3.
    pub confirmation: ConfirmationConfig,
    /// §4–5.
    pub demand: DemandConfig,
    /// §6.
    pub switching: SwitchingConfig,
    /// §7.
    pub hesitation: HesitationConfig,
    /// §8 composite.
    pub composite: CompositeConfig,
    /// §8 windowed indicators.
    pub window: WindowConfig,
    /// §8 dominant indicator.
    pub dominant: DominantConfig,
}

impl AssessConfig {
    /// Loads and validates a TOML file.
    pub fn from_toml_file(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = crate::error::read_text(path)?;
        Self::parse(&text, path)
    }

    /// Parses and validates a TOML document.
    pub fn from_toml_str(text: &str) -> Result<Self> {
        Self::parse(text, Path::new("<string>"))
    }

    fn parse(text: &str, origin: &Path) -> Result<Self> {
        let cfg: Self = crate::error::parse_toml(text, origin)?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The configuration as TOML, every key with its value.
    pub fn to_toml_string(&self) -> Result<String> {
        toml::to_string_pretty(self).map_err(|e| AssessError::Serialize {
            what: "assessment configuration",
            message: e.to_string(),
        })
    }

    /// Checks every rule; the error names the key and the rule.
    pub fn validate(&self) -> Result<()> {
        let f = &self.fusion;
        check_weights("fusion.weights", &f.weights)?;
        check_weights("fusion.turn_weights", &f.turn_weights)?;
        unit_closed("fusion.min_confidence", f.min_confidence)?;
        positive("fusion.turn_yaw_rate_deg_s", f.turn_yaw_rate_deg_s)?;
        if f.turn_lookback_frames == 0 || f.turn_lookback_frames > MAX_FRAMES {
            return Err(AssessError::invalid(
                "fusion.turn_lookback_frames",
                format!(
                    "must be ≥ 1 and ≤ {MAX_FRAMES} (got {})",
                    f.turn_lookback_frames
                ),
            ));
        }
        if !(f.tau > 0.0 && f.tau <= 1.0) {
            return Err(AssessError::invalid(
                "fusion.tau",
                format!("τ must lie in (0, 1] (got {})", f.tau),
            ));
        }
        let m = self.confirmation.window_frames;
        if m == 0 || m > MAX_FRAMES {
            return Err(AssessError::invalid(
                "confirmation.window_frames",
                format!("M must be ≥ 1 and ≤ {MAX_FRAMES} (got {m})"),
            ));
        }
        positive(
            "demand.max_frame_interval_s",
            self.demand.max_frame_interval_s,
        )?;
        non_negative("demand.action_radius_m", self.demand.action_radius_m)?;
        let s = &self.switching;
        for (k, v) in [
            ("switching.cost_high", s.cost_high),
            ("switching.cost_int", s.cost_int),
            ("switching.cost_base", s.cost_base),
        ] {
            finite(k, v)?;
        }
        if !(s.cost_high > s.cost_int && s.cost_int > s.cost_base && s.cost_base > 0.0) {
            let key = if s.cost_base <= 0.0 {
                "switching.cost_base"
            } else if s.cost_int <= s.cost_base {
                "switching.cost_int"
            } else {
                "switching.cost_high"
            };
            return Err(AssessError::invalid(
                key,
                format!(
                    "costs must satisfy c_high > c_int > c_base > 0 (got c_high {}, c_int {}, c_base {})",
                    s.cost_high, s.cost_int, s.cost_base
                ),
            ));
        }
        let h = &self.hesitation;
        positive(
            "hesitation.one_euro.min_cutoff_hz",
            h.one_euro.min_cutoff_hz,
        )?;
        non_negative("hesitation.one_euro.beta", h.one_euro.beta)?;
        positive("hesitation.one_euro.d_cutoff_hz", h.one_euro.d_cutoff_hz)?;
        non_negative("hesitation.k_v", h.k_v)?;
        positive("hesitation.v_min_m_s", h.v_min_m_s)?;
        if !(h.v_max_m_s.is_finite() && h.v_max_m_s >= h.v_min_m_s) {
            return Err(AssessError::invalid(
                "hesitation.v_max_m_s",
                format!(
                    "must be finite and ≥ v_min_m_s (got {} < {})",
                    h.v_max_m_s, h.v_min_m_s
                ),
            ));
        }
        positive("hesitation.median_horizon_s", h.median_horizon_s)?;
        non_negative("hesitation.min_sample_time_s", h.min_sample_time_s)?;
        non_negative("hesitation.min_duration_s", h.min_duration_s)?;
        positive("hesitation.epsilon_s", h.epsilon_s)?;
        let c = &self.composite;
        let w = c.weights.to_array();
        for (name, v) in COMPONENT_KEYS.iter().zip(w) {
            if !(v.is_finite() && v >= 0.0) {
                return Err(AssessError::invalid(
                    format!("composite.weights.{name}"),
                    format!("weights must be ≥ 0 (got {v})"),
                ));
            }
        }
        let sum: f64 = w.iter().sum();
        if (sum - 1.0).abs() > 1e-9 {
            return Err(AssessError::invalid(
                "composite.weights",
                format!("weights must sum to 1 within 1e-9 (got {sum})"),
            ));
        }
        positive("composite.asd_ref_per_s", c.asd_ref_per_s)?;
        if !(c.medium_from > 0.0 && c.medium_from < c.high_from && c.high_from <= 1.0) {
            return Err(AssessError::invalid(
                "composite.medium_from",
                format!(
                    "category bounds must satisfy 0 < medium_from < high_from ≤ 1 (got {}, {})",
                    c.medium_from, c.high_from
                ),
            ));
        }
        positive("window.horizon_s", self.window.horizon_s)?;
        positive("window.max_rate_hz", self.window.max_rate_hz)?;
        if self.window.horizon_s * self.window.max_rate_hz > 10_000_000.0 {
            return Err(AssessError::invalid(
                "window.max_rate_hz",
                "horizon_s × max_rate_hz must stay ≤ 1e7 frames",
            ));
        }
        if h.median_horizon_s * self.window.max_rate_hz > 10_000_000.0 {
            return Err(AssessError::invalid(
                "hesitation.median_horizon_s",
                "median_horizon_s × window.max_rate_hz must stay ≤ 1e7 samples",
            ));
        }
        if h.min_duration_s >= self.window.horizon_s {
            return Err(AssessError::invalid(
                "hesitation.min_duration_s",
                "t_min must be shorter than the window horizon",
            ));
        }
        let d = &self.dominant;
        non_negative("dominant.calibration_s", d.calibration_s)?;
        for (name, v) in COMPONENT_KEYS.iter().zip(d.baseline.to_array()) {
            unit_closed(&format!("dominant.baseline.{name}"), v)?;
        }
        non_negative("dominant.none_threshold", d.none_threshold)?;
        non_negative("dominant.hold_s", d.hold_s)?;
        non_negative("dominant.margin", d.margin)?;
        Ok(())
    }
}

/// The most frames `confirmation.window_frames` (M) and `fusion.turn_lookback_frames` may be:
/// 10 000, over 40 s at the 240 Hz `window.max_rate_hz` default. Each sizes a buffer of the
/// assessor; the bound keeps a typo from aborting the process allocating it (issue 10).
pub const MAX_FRAMES: usize = 10_000;

/// Component names as used in config keys and logs, in component order.
pub const COMPONENT_KEYS: [&str; 5] = ["aed", "tid", "icd", "asd", "ohd"];

fn check_weights(key: &str, w: &CueWeights) -> Result<()> {
    for (name, v) in [("head", w.head), ("body", w.body), ("hand", w.hand)] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(AssessError::invalid(
                format!("{key}.{name}"),
                format!("weights must be ≥ 0 (got {v})"),
            ));
        }
    }
    let sum = w.head + w.body + w.hand;
    if (sum - 1.0).abs() > 1e-9 {
        return Err(AssessError::invalid(
            key,
            format!("weights must sum to 1 within 1e-9 (got {sum})"),
        ));
    }
    Ok(())
}

fn finite(key: &str, v: f64) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(AssessError::invalid(
            key,
            format!("must be finite (got {v})"),
        ))
    }
}

fn positive(key: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(AssessError::invalid(
            key,
            format!("must be finite and > 0 (got {v})"),
        ))
    }
}

fn non_negative(key: &str, v: f64) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(AssessError::invalid(
            key,
            format!("must be finite and ≥ 0 (got {v})"),
        ))
    }
}

fn unit_closed(key: &str, v: f64) -> Result<()> {
    if (0.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(AssessError::invalid(
            key,
            format!("must lie in [0, 1] (got {v})"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_that_become_allocations_are_bounded_and_the_error_names_the_key() {
        // Each of these sizes a buffer in `Assessor::new`; at a077dd5 a huge value passed
        // validation and then aborted the process allocating it (issue 10).
        type Set = fn(&mut AssessConfig);
        let cases: [(&str, Set); 3] = [
            ("confirmation.window_frames", |c| {
                c.confirmation.window_frames = 10_001
            }),
            ("fusion.turn_lookback_frames", |c| {
                c.fusion.turn_lookback_frames = 10_001
            }),
            ("hesitation.median_horizon_s", |c| {
                c.hesitation.median_horizon_s = 1e20
            }),
        ];
        for (key, set) in cases {
            let mut cfg = AssessConfig::default();
            set(&mut cfg);
            let e = cfg.validate().unwrap_err().to_string();
            assert!(e.contains(key), "{key}: {e}");
        }
        let mut cfg = AssessConfig::default();
        cfg.confirmation.window_frames = 10_000;
        cfg.fusion.turn_lookback_frames = 10_000;
        assert!(cfg.validate().is_ok());
    }
}
