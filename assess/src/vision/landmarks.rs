//! Landmark sets in image pixels, as the pipeline returns them.

use super::roi::Roi;

/// One landmark: image position [px], relative depth and scores.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Landmark {
    /// Column [px] (MediaPipe's normalised x times the image width).
    pub x: f64,
    /// Row [px] (normalised y times the image height).
    pub y: f64,
    /// Depth relative to the set's reference point, in the same scale as x [px]; smaller is
    /// nearer the camera. Not metric.
    pub z: f64,
    /// Probability that the landmark is visible (not occluded) [-]; 1 where the model has no
    /// visibility output.
    pub visibility: f64,
    /// Probability that the landmark is inside the image [-]; 1 where the model has no
    /// presence output.
    pub presence: f64,
}

/// The 33 pose landmarks of BlazePose (MediaPipe's order: 0 nose, 11/12 shoulders,
/// 15/16 wrists, 23/24 hips, ...; "left" is the person's left).
#[derive(Debug, Clone, PartialEq)]
pub struct PoseLandmarks {
    /// The landmarks.
    pub points: [Landmark; 33],
    /// Pose presence score [-].
    pub score: f64,
    /// The crop the landmarks came from.
    pub roi: Roi,
}

/// The 21 landmarks of one hand (0 wrist, 5/9/13/17 knuckles, 4/8/12/16/20 finger tips).
#[derive(Debug, Clone, PartialEq)]
pub struct HandLandmarks {
    /// The landmarks.
    pub points: [Landmark; 21],
    /// Hand presence score [-].
    pub score: f64,
    /// Probability that this is the person's right hand, for an unmirrored camera image [-].
    pub right_hand: f64,
    /// The crop the landmarks came from.
    pub roi: Roi,
}

/// The 468 face-mesh landmarks (33/263 outer eye corners, 1 nose tip, ...).
#[derive(Debug, Clone, PartialEq)]
pub struct FaceLandmarks {
    /// The landmarks (468).
    pub points: Vec<Landmark>,
    /// Face presence score [-].
    pub score: f64,
    /// The crop the landmarks came from.
    pub roi: Roi,
}

/// Everything found on one frame, for the operator (single person).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Landmarks {
    /// Body pose.
    pub pose: Option<PoseLandmarks>,
    /// Face mesh.
    pub face: Option<FaceLandmarks>,
    /// Hands (at most two).
    pub hands: Vec<HandLandmarks>,
}
