//! Helpers of the tests comparing our landmarks with mediapipe's fixtures frame by frame
//! (`vision_moving.rs`, `vision_scenes.rs`): distances in px and the statistics of an error
//! series in the units of issue 13's tolerances.

use assess::vision::Landmark;
use assess::vision::models::model_dir;
use assess::vision::pipeline::{Mode, Pipeline, PipelineConfig};
use serde_json::Value;

/// Our pipeline in tracking mode (as mediapipe's video mode), default models.
pub(crate) fn tracking_pipeline() -> Pipeline {
    Pipeline::load(
        &model_dir(),
        PipelineConfig {
            mode: Mode::Tracking,
            ..PipelineConfig::default()
        },
    )
    .unwrap()
}

/// A fixture point `[x, y]` [px].
pub(crate) fn xy(v: &Value) -> [f64; 2] {
    [v[0].as_f64().unwrap(), v[1].as_f64().unwrap()]
}

/// The distance between two points [px].
pub(crate) fn d(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The largest distance over `idx` between ours and the reference [px].
pub(crate) fn worst(ours: &[Landmark], theirs: &[Value], idx: impl Iterator<Item = usize>) -> f64 {
    idx.map(|i| d([ours[i].x, ours[i].y], xy(&theirs[i])))
        .fold(0.0, f64::max)
}

/// Median, max and the number over 5 % of one error series (all 0 for an empty one).
pub(crate) struct Stats {
    pub(crate) median: f64,
    pub(crate) max: f64,
    pub(crate) over_5pct: usize,
    pub(crate) n: usize,
}

impl Stats {
    pub(crate) fn of(v: &[f64]) -> Stats {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        Stats {
            median: s.get(s.len() / 2).copied().unwrap_or(0.0),
            max: s.last().copied().unwrap_or(0.0),
            over_5pct: s.iter().filter(|&&e| e > 0.05).count(),
            n: s.len(),
        }
    }
}
