//! Test helpers: assessments built directly (every field of `assess::Assessment` is public).

#![allow(dead_code, unreachable_pub)]

use assess::{Assessment, Dominant, Indicator, Indicators};

/// An assessment at `t` whose dominant indicator is `dominant`, with contributions `e`.
pub fn assessment(t: f64, dominant: Option<Indicator>, e: [f64; 5]) -> Assessment {
    Assessment {
        t,
        frames: 0,
        rejected_frames: 0,
        last_rejected: false,
        dt_s: 0.0,
        valid: true,
        present: [true; 3],
        turning: false,
        weights: [0.6, 0.25, 0.15],
        raw: None,
        raw_score: 0.0,
        confirmed: None,
        perceptual: (None, false),
        action: (None, false),
        active_hand: None,
        hand_speed_m_s: None,
        speed_threshold_m_s: 0.1,
        low_motion: false,
        hesitating: false,
        collaborating: false,
        switch_cost: None,
        switches: 0,
        cumulative: Indicators::default(),
        windowed: Indicators::default(),
        area_demand: Vec::new(),
        area_demand_windowed: Vec::new(),
        dominant: Dominant {
            indicator: dominant,
            strength: dominant.map_or(0.0, |k| e[k as usize]),
            held_for_s: 0.0,
            candidate: dominant,
            contributions: e,
            baseline: Some([0.5, 0.15, 0.15, 0.2, 0.1]),
            calibrating: false,
        },
        window_overflow: false,
    }
}

/// Contributions with `k` at `strength` and the others at 0.
pub fn only(k: Indicator, strength: f64) -> [f64; 5] {
    let mut e = [0.0; 5];
    e[k as usize] = strength;
    e
}
