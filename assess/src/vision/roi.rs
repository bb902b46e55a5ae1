//! Rotated regions of interest, in image pixels, as MediaPipe's `NormalizedRect` scaled to the
//! image.

/// A rotated rectangle in image pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Roi {
    /// Centre x [px].
    pub cx: f64,
    /// Centre y [px].
    pub cy: f64,
    /// Width [px].
    pub width: f64,
    /// Height [px].
    pub height: f64,
    /// Rotation, clockwise in the image (y down) [rad].
    pub rotation: f64,
}
