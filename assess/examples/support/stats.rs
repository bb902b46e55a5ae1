//! Statistics helpers shared by the calibration examples (`cue_noise`, `kth_kinematics`),
//! included from each with `#[path = "support/stats.rs"] mod stats;`.

/// Arithmetic mean (NaN for an empty slice).
pub(crate) fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}
