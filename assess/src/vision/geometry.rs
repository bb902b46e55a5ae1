//! 3-D geometry for the cues: rigid fits (Kabsch/Umeyama with nalgebra) and depth sampling.

use nalgebra::{Matrix3, Point3, Rotation3, UnitQuaternion, Vector3};

use super::frame::{DepthImage, Intrinsics};

/// A similarity transform `p ↦ scale · R · p + t` found by [`fit_similarity`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Similarity {
    /// Rotation R.
    pub rotation: UnitQuaternion<f64>,
    /// Translation t [m].
    pub translation: Vector3<f64>,
    /// Scale [-].
    pub scale: f64,
    /// Root-mean-square residual of the fitted points [m].
    pub rms: f64,
}

impl Similarity {
    /// Applies the transform to a point.
    pub(crate) fn apply(&self, p: &Point3<f64>) -> Point3<f64> {
        Point3::from(self.rotation * p.coords * self.scale + self.translation)
    }
}

/// Least-squares similarity (Umeyama 1991; Kabsch for the rotation) mapping `model` points
/// onto `observed` points, with weights. `None` with fewer than three points, zero total
/// weight or degenerate (collinear) points. With `allow_scale = false` the scale is 1.
pub(crate) fn fit_similarity(
    model: &[Point3<f64>],
    observed: &[Point3<f64>],
    weights: &[f64],
    allow_scale: bool,
) -> Option<Similarity> {
    let n = model.len();
    if n < 3 || observed.len() != n || weights.len() != n {
        return None;
    }
    let wsum: f64 = weights.iter().sum();
    if wsum.is_nan() || wsum <= 0.0 {
        return None;
    }
    let mut mc = Vector3::zeros();
    let mut oc = Vector3::zeros();
    for ((m, o), w) in model.iter().zip(observed).zip(weights) {
        mc += m.coords * *w;
        oc += o.coords * *w;
    }
    mc /= wsum;
    oc /= wsum;
    let mut cov = Matrix3::zeros();
    let mut var_m = 0.0;
    for ((m, o), w) in model.iter().zip(observed).zip(weights) {
        let dm = m.coords - mc;
        let dob = o.coords - oc;
        cov += dob * dm.transpose() * *w;
        var_m += dm.norm_squared() * *w;
    }
    cov /= wsum;
    var_m /= wsum;
    let svd = cov.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    // Degenerate when the second singular value vanishes (collinear points).
    let mut sv = svd.singular_values;
    sv.as_mut_slice().sort_by(|a, b| b.total_cmp(a));
    if sv[1] <= 1e-12 * sv[0].max(1e-300) {
        return None;
    }
    let r = u * d * v_t;
    let scale = if allow_scale && var_m > 0.0 {
        (svd.singular_values.component_mul(&d.diagonal())).sum() / var_m
    } else {
        1.0
    };
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let translation = oc - rotation * mc * scale;
    let mut sim = Similarity {
        rotation,
        translation,
        scale,
        rms: 0.0,
    };
    let mut sq = 0.0;
    for ((m, o), w) in model.iter().zip(observed).zip(weights) {
        sq += (sim.apply(m) - o).norm_squared() * *w;
    }
    sim.rms = (sq / wsum).sqrt();
    Some(sim)
}

/// The median valid depth [m] in a (2r+1)² patch around pixel (u, v) [px], ignoring zeros
/// and values outside `range_m`; `None` when fewer than a third of the patch is valid.
pub(crate) fn patch_depth(
    depth: &DepthImage,
    u: f64,
    v: f64,
    radius: u32,
    range_m: (f64, f64),
    scratch: &mut Vec<f64>,
) -> Option<f64> {
    if !u.is_finite() || !v.is_finite() {
        return None;
    }
    let (cu, cv) = (u.floor() as i64, v.floor() as i64);
    let r = i64::from(radius);
    scratch.clear();
    let mut total = 0usize;
    for y in cv - r..=cv + r {
        for x in cu - r..=cu + r {
            total += 1;
            if x < 0 || y < 0 {
                continue;
            }
            if let Some(z) = depth.depth_m(x as u32, y as u32)
                && z >= range_m.0
                && z <= range_m.1
            {
                scratch.push(z);
            }
        }
    }
    if scratch.is_empty() || scratch.len() * 3 < total {
        return None;
    }
    scratch.sort_by(f64::total_cmp);
    let n = scratch.len();
    Some(if n % 2 == 1 {
        scratch[n / 2]
    } else {
        (scratch[n / 2 - 1] + scratch[n / 2]) / 2.0
    })
}

/// The camera-frame point [m] at pixel (u, v) [px], with depth from a patch median.
pub fn lift(
    depth: &DepthImage,
    intrinsics: &Intrinsics,
    u: f64,
    v: f64,
    radius: u32,
    range_m: (f64, f64),
    scratch: &mut Vec<f64>,
) -> Option<Point3<f64>> {
    patch_depth(depth, u, v, radius, range_m, scratch).map(|z| intrinsics.deproject(u, v, z))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn similarity_recovers_a_known_transform() {
        // Model: a tetrahedron [cm]; observed: scaled by 0.01, rotated 30° about z, shifted.
        let model = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(10.0, 0.0, 0.0),
            Point3::new(0.0, 10.0, 0.0),
            Point3::new(0.0, 0.0, 10.0),
        ];
        let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians());
        let t = Vector3::new(0.1, -0.2, 1.0);
        let obs: Vec<_> = model
            .iter()
            .map(|p| Point3::from(r * p.coords * 0.01 + t))
            .collect();
        let s = fit_similarity(&model, &obs, &[1.0; 4], true).unwrap();
        assert!((s.scale - 0.01).abs() < 1e-12);
        assert!(s.rotation.angle_to(&r) < 1e-9);
        assert!((s.translation - t).norm() < 1e-12);
        assert!(s.rms < 1e-12);
        // A reflection is never returned: mirrored points give a proper rotation.
        let mirrored: Vec<_> = obs.iter().map(|p| Point3::new(-p.x, p.y, p.z)).collect();
        let m = fit_similarity(&model, &mirrored, &[1.0; 4], true).unwrap();
        assert!((m.rotation.to_rotation_matrix().matrix().determinant() - 1.0).abs() < 1e-9);
        // Collinear points are degenerate.
        let line = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(2.0, 0.0, 0.0),
        ];
        assert!(fit_similarity(&line, &line, &[1.0; 3], false).is_none());
    }

    #[test]
    fn patch_median_ignores_invalid_depth() {
        // 3 × 3 image: centre row 1000, 1010, 0 (invalid) mm; others 2000 mm (outside the
        // 0.2–1.5 m range). Radius 1 around (1, 1): valid 1.000 and 1.010 → median 1.005 m,
        // but 2 of 9 valid is under a third → None. Widen the range: all 8 valid values
        // (1.000, 1.010, 6 × 2.000) → median 2.0.
        let depth = DepthImage {
            width: 3,
            height: 3,
            data: vec![2000, 2000, 2000, 1000, 1010, 0, 2000, 2000, 2000],
            scale_m: 0.001,
        };
        let mut s = Vec::new();
        assert_eq!(patch_depth(&depth, 1.0, 1.0, 1, (0.2, 1.5), &mut s), None);
        assert_eq!(
            patch_depth(&depth, 1.0, 1.0, 1, (0.2, 3.0), &mut s),
            Some(2.0)
        );
        // Radius 0 at (0, 1): 1.0 m.
        assert_eq!(
            patch_depth(&depth, 0.0, 1.0, 0, (0.2, 3.0), &mut s),
            Some(1.0)
        );
        // Outside the image or NaN: None, no panic.
        assert_eq!(patch_depth(&depth, -5.0, 1.0, 0, (0.2, 3.0), &mut s), None);
        assert_eq!(
            patch_depth(&depth, f64::NAN, 1.0, 1, (0.2, 3.0), &mut s),
            None
        );
    }
}
