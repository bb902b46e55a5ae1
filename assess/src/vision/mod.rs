//! The camera front-end (feature `vision`): RGB-D frames → face, pose and hand landmarks →
//! head, upper-body and hand cues in the workspace frame → [`CueFrame`](crate::CueFrame)s.
//!
//! [`Perception`] is the whole chain for one camera: open a [`source`] with [`source::open`],
//! then [`Perception::step`] each frame into landmarks and cues. Around it:
//! - [`source`]: frames from a RealSense camera or `.bag` file (feature `realsense`), a video
//!   file with an optional depth sequence, an image folder, or a plain webcam;
//! - [`pipeline`]: the landmark stage, MediaPipe's pose, face-mesh and hand models (converted
//!   to ONNX, run with ONNX Runtime from [`models`]) with SSD detection, rotated-ROI crops,
//!   ROI tracking between frames and the choice of the operator among several people;
//! - [`cues`]: 3-D lifting from depth, head pose (Kabsch fit to the canonical face), torso
//!   frame, hand points, confidences and One-Euro smoothing, in the workspace frame;
//! - [`calib`]: camera-to-workspace extrinsics from an ArUco/ChArUco board;
//! - [`output`]: the landmark CSV every camera run writes, and image outputs (only where a
//!   user asked for images); [`annotate`] and [`draw`]: the monitoring overlay.
//!
//! The detector decoding, anchors, crops and geometry inside [`pipeline`] and [`cues`] are
//! private.
//!
//! ```
//! use assess::vision::cues::CueQuality;
//! use assess::vision::pipeline::PipelineConfig;
//! use assess::vision::source::{self, SourceSpec};
//! use assess::vision::{Extrinsics, Perception};
//!
//! // The five bundled photos, as a folder source (intrinsics from a 69° field of view).
//! let photos = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/images");
//! let spec = SourceSpec::Images { path: photos.into(), depth: None };
//! let mut opened = source::open(&spec, 69.0)?;
//! assert_eq!(opened.len, Some(5));
//! // Still photos: every frame is decided afresh (no tracking between frames).
//! let mut perception =
//!     Perception::load(PipelineConfig::static_images(), Extrinsics::identity(), None, None)?;
//! let frame = opened.source.next_frame()?.expect("a first photo");
//! let seen = perception.step(&frame)?;
//! let pose = seen.landmarks.pose.expect("the person in business-person.png");
//! assert_eq!(pose.points.len(), 33);
//! // Without depth the cues are 2-D only, and say so.
//! assert_eq!(seen.cues.quality, CueQuality::Image2d);
//! # Ok::<(), assess::AssessError>(())
//! ```

mod anchors;
pub mod calib;
pub mod cues;
mod detect;
pub mod draw;
mod frame;
mod geometry;
mod landmarks;
pub mod models;
pub mod output;
mod perception;
pub mod pipeline;
mod roi;
pub mod source;

pub use detect::Detection;
pub use frame::{CameraFrame, DepthImage, Extrinsics, Intrinsics, RgbImage};
pub use geometry::lift;
pub use landmarks::{FaceLandmarks, HandLandmarks, Landmark, Landmarks, PoseLandmarks};
pub use perception::{FixedIntrinsics, Perceived, Perception, Pinhole, annotate};
pub use roi::Roi;
pub use source::FrameSource;
