//! §1 Cue-to-area evidence.
//!
//! - head and body: δ = ∠(o, r_i − x) [rad] in [0, π], S = max(0, 1 − δ/π);
//! - hand: δ = dist(x_m, A_i) [m], 0 inside the box, S = max(0, 1 − δ/D_ws).

use crate::Vec3;

/// The angle between two vectors [rad], in [0, π]; 0 when either is the zero vector.
///
/// Computed as atan2(‖a × b‖, a · b), which stays accurate near 0 and π.
pub fn angle(a: &Vec3, b: &Vec3) -> f64 {
    a.cross(b).norm().atan2(a.dot(b))
}

/// Evidence of an orientation cue (head or body) for an area: S = max(0, 1 − ∠(o, r − x)/π) [-].
///
/// `facing` is o (any length > 0), `position` is x [m] and `centre` is the area's representative
/// centre r [m].
pub fn orientation_evidence(facing: &Vec3, position: &Vec3, centre: &Vec3) -> f64 {
    (1.0 - angle(facing, &(centre - position)) / std::f64::consts::PI).max(0.0)
}

/// Evidence of the hand cue for an area from its distance to the box [m] and the workspace
/// diagonal D_ws [m]: S = max(0, 1 − d/D_ws) [-].
pub fn hand_evidence(distance_m: f64, diagonal_m: f64) -> f64 {
    (1.0 - distance_m / diagonal_m).max(0.0)
}
