//! Cue sources of a trial: the **simulated operator** (the default, `operator.rs`), a
//! **recorded cue file** (`hrc-adapt trial --cues <file.csv>`, the cue CSV format of
//! `assess::io::cue_csv`) or a **live camera** (`--cues camera`, feature `vision`: see
//! `live.rs`).
//!
//! A recorded file is replayed **by time, sample-and-hold**: at each assessment instant (the
//! cue rate, 30 Hz) the runtime uses the frame with the latest `t` ≤ trial time, where the
//! file's times are taken relative to its first frame (its first frame is at trial time 0).
//! Only the head, upper-body and hand cues are used (workspace frame); the file's `collaborating` / `incomplete` columns are ignored,
//! because the robot context comes from the live task. The replay ends at the first
//! assessment instant after the file's last frame (finish reason `cues_ended`).
//!
//! A recorded operator does **not react to the robot**: no grasp is timed to a presented part,
//! no hesitation follows a fast approach. Handovers complete only if the recorded hands happen
//! to reach the presented part.

use std::path::{Path, PathBuf};

use crate::error::ResultExt as _;
use assess::CueFrame;

/// Where a trial's operator cues come from.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) enum CueSource {
    /// The seeded simulated operator (closed loop: it reacts to the robot).
    #[default]
    Simulated,
    /// A recorded cue CSV, replayed by time (open loop).
    Recorded(PathBuf),
    /// A live camera, perceived in its own thread (feature `vision`).
    Camera(CameraSpec),
}

/// A live cue source: the camera, how to read it, whether to store its video.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct CameraSpec {
    /// The frame source (`Camera`, `Webcam { device, size }`; the tests use an image folder).
    pub(crate) input: crate::vision_cmd::CueInput,
    /// Extrinsics, intrinsics, model variant.
    pub(crate) camera: crate::vision_cmd::CameraArgs,
    /// Store the raw camera images here (`.avi` or a PNG folder); `None`: never (privacy).
    pub(crate) store_video: Option<PathBuf>,
    /// Refuse a source without depth (set for a real robot: 2-D-only positions, estimated from
    /// assumed body sizes, are too rough for separation monitoring).
    pub(crate) require_depth: bool,
    /// The operator's station from the trial's workspace (set when the trial loads it), which
    /// makes a person there the preferred operator.
    pub(crate) station: Option<assess::Station>,
}

/// A recorded cue file being replayed.
#[derive(Debug, Clone)]
pub(crate) struct RecordedCues {
    frames: Vec<CueFrame>,
    /// The first frame's `t` (trial time 0) [s].
    t0: f64,
    /// Index of the frame currently held.
    next: usize,
    label: String,
}

impl RecordedCues {
    /// Reads `path` (`assess::io::cue_csv::read`); fails when it holds no frame.
    pub(crate) fn load(path: &Path) -> crate::Result<Self> {
        let frames = assess::io::cue_csv::read(path)
            .with_context(|| format!("reading the cue file {}", path.display()))?;
        let first = frames.first().ok_or_else(|| {
            crate::Error::data(format!("the cue file {}", path.display()), "holds no frame")
        })?;
        let name = path.file_name().map_or_else(
            || path.display().to_string(),
            |n| n.to_string_lossy().into(),
        );
        Ok(Self {
            t0: first.t,
            frames,
            next: 0,
            label: format!("recorded:{name}"),
        })
    }

    /// `recorded:<file name>`: the run's `cue_source`.
    pub(crate) fn label(&self) -> &str {
        &self.label
    }

    /// The file's last frame, in trial time [s].
    pub(crate) fn last_t(&self) -> f64 {
        self.frames.last().map_or(0.0, |f| f.t - self.t0)
    }

    /// True once trial time `tc` [s] is past the file's last frame.
    pub(crate) fn ended(&self, tc: f64) -> bool {
        tc > self.last_t() + 1e-9
    }

    /// Writes the operator cues held at trial time `tc` (the frame with the latest relative
    /// `t` ≤ `tc`) into `out` (`out.t = tc`; `out.robot` is left to the caller) and returns
    /// that frame's trial time [s]. `tc` must not decrease between calls.
    pub(crate) fn hold(&mut self, tc: f64, out: &mut CueFrame) -> f64 {
        while self.next + 1 < self.frames.len()
            && self.frames[self.next + 1].t - self.t0 <= tc + 1e-9
        {
            self.next += 1;
        }
        let f = &self.frames[self.next];
        out.t = tc;
        out.head = f.head;
        out.body = f.body;
        out.hands = f.hands;
        f.t - self.t0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replay_is_sample_and_hold_relative_to_the_first_frame() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.csv");
        std::fs::write(
            &p,
            "t,head_x,head_y,head_z,head_fx,head_fy,head_fz,head_conf\n\
             10.0,1,0,1.5,1,0,0,0.9\n10.1,2,0,1.5,1,0,0,0.9\n10.25,3,0,1.5,1,0,0,0.9\n",
        )
        .unwrap();
        let mut r = RecordedCues::load(&p).unwrap();
        assert_eq!(r.label(), "recorded:c.csv");
        let mut f = CueFrame::empty(0.0);
        let x = |f: &CueFrame| f.head.as_ref().unwrap().position.x;
        assert_eq!(r.hold(0.0, &mut f), 0.0);
        assert_eq!((f.t, x(&f)), (0.0, 1.0));
        r.hold(0.09, &mut f);
        assert_eq!(x(&f), 1.0);
        r.hold(0.1, &mut f);
        assert_eq!(x(&f), 2.0);
        r.hold(0.2, &mut f);
        assert_eq!((f.t, x(&f)), (0.2, 2.0));
        assert!(!r.ended(0.25));
        r.hold(0.25, &mut f);
        assert_eq!(x(&f), 3.0);
        assert!(r.ended(0.26));
    }
}
