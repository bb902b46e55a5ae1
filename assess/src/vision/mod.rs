//! The camera front-end (feature `vision`): RGB-D frames → face, pose and hand landmarks →
//! head, upper-body and hand cues in the workspace frame → [`CueFrame`](crate::CueFrame)s.
//!
//! The stages, in data-flow order:
//! - [`source`]: frames from a RealSense camera or `.bag` file (feature `realsense`), a video
//!   file with an optional depth sequence, an image folder, or a plain webcam;
//! - [`pipeline`]: MediaPipe's pose, face-mesh and hand models (converted to ONNX, run with
//!   ONNX Runtime), with SSD detection, rotated-ROI crops and ROI tracking between frames;
//! - [`cues`]: 3-D lifting from depth, head pose (Kabsch fit to the canonical face), torso
//!   frame, hand points, confidences and One-Euro smoothing, in the workspace frame;
//! - [`calib`]: camera-to-workspace extrinsics from an ArUco/ChArUco board;
//! - [`draw`]: overlays for the monitoring view.

pub mod anchors;
pub mod calib;
pub mod cues;
pub mod detect;
pub mod draw;
pub mod frame;
pub mod geometry;
pub mod landmarks;
pub mod models;
pub mod pipeline;
pub mod roi;
pub mod source;

pub use frame::{CameraFrame, DepthImage, Extrinsics, Intrinsics, RgbImage};
pub use landmarks::{FaceLandmarks, HandLandmarks, Landmark, Landmarks, PoseLandmarks};
pub use roi::Roi;
pub use source::FrameSource;
