//! Frame sources: where [`CameraFrame`]s come from.
//!
//! Every source yields frames with strictly increasing camera timestamps and ends with
//! `Ok(None)`. A frame that cannot be decoded is an error naming the source and the frame.

use super::frame::CameraFrame;
use crate::Result;

/// A stream of camera frames.
pub trait FrameSource {
    /// The next frame, `Ok(None)` at the end of a recording (live sources never end).
    fn next_frame(&mut self) -> Result<Option<CameraFrame>>;

    /// A one-line description for logs ("RealSense D435i 123456", "video run3.mp4 (30 fps)").
    fn describe(&self) -> String;

    /// Whether frames carry depth (false: cues are 2-D-only, see `CueQuality`).
    fn has_depth(&self) -> bool;
}

pub mod capture;
pub mod folder;
#[cfg(feature = "realsense")]
pub mod realsense;
