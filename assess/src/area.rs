//! Calibrated workspace areas ([`spec`](crate::spec), "Calibrated areas") and their TOML
//! calibration file.
//!
//! ```toml
//! # Optional: the workspace diagonal D_ws [m]; default: the diagonal of the bounding box of all areas.
//! diagonal_m = 2.0
//!
//! [[area]]
//! name = "assembly"
//! role = "assembly"            # assembly | tool_identification | instruction | collaboration
//! min_m = [0.2, -0.3, 0.75]    # axis-aligned box by its corners [m] ...
//! max_m = [0.6, 0.3, 0.95]
//!
//! [[area]]
//! name = "handover"
//! role = "collaboration"
//! centre_m = [0.5, 0.6, 1.0]   # ... or an oriented box: centre [m], full size [m], yaw about z [deg]
//! size_m = [0.4, 0.4, 0.4]
//! yaw_deg = 30.0
//! representative_centre_m = [0.5, 0.6, 1.1]   # optional r_i; default: the box centre
//!
//! # Optional: the operator's station, where their torso is while they work. The camera
//! # front-end then prefers a person there as the operator (`vision::pipeline::rank_operators`).
//! [station]
//! position_m = [0.0, 0.0, 1.1]   # [m], workspace frame
//! radius_m = 0.6                 # [m], in (0, 5]; default 0.6
//! ```

use std::path::Path;

use nalgebra::{Rotation3, Vector3};
use serde::Deserialize;

use crate::Vec3;
use crate::error::{AssessError, Result};

/// The functional role of an area, which the indicators and switching costs refer to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AreaRole {
    /// A_ass: the assembly area (AED).
    Assembly,
    /// A_id: tool identification / storage (TID).
    ToolIdentification,
    /// A_ins: instruction (ICD).
    Instruction,
    /// A_col: robot collaboration / handover (COL).
    Collaboration,
}

impl AreaRole {
    /// All roles, in indicator order (ass, id, ins, col).
    pub const ALL: [AreaRole; 4] = [
        AreaRole::Assembly,
        AreaRole::ToolIdentification,
        AreaRole::Instruction,
        AreaRole::Collaboration,
    ];

    /// Short name as in the paper (`ass`, `id`, `ins`, `col`).
    pub fn short(self) -> &'static str {
        match self {
            AreaRole::Assembly => "ass",
            AreaRole::ToolIdentification => "id",
            AreaRole::Instruction => "ins",
            AreaRole::Collaboration => "col",
        }
    }
}

/// Index of an area in its [`Workspace`], in calibration-file order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct AreaId(pub usize);

/// An oriented box in the workspace frame.
#[derive(Debug, Clone, PartialEq)]
pub struct AreaBox {
    centre: Vec3,
    half_size: Vec3,
    /// Rotation from the box frame to the workspace frame.
    rotation: Rotation3<f64>,
}

impl AreaBox {
    /// An axis-aligned box from its corners [m]. Fails unless `min < max` on every axis and all
    /// values are finite.
    pub fn from_corners(min: Vec3, max: Vec3) -> Result<Self> {
        let size = max - min;
        Self::new((min + max) / 2.0, size, 0.0).map_err(|e| match e {
            AssessError::InvalidValue { rule, .. } => AssessError::invalid("min_m/max_m", rule),
            other => other,
        })
    }

    /// An oriented box from its centre [m], full size [m] and yaw about the z axis [rad].
    pub fn new(centre: Vec3, size: Vec3, yaw_rad: f64) -> Result<Self> {
        if !(centre.iter().all(|v| v.is_finite())
            && size.iter().all(|v| v.is_finite())
            && yaw_rad.is_finite())
        {
            return Err(AssessError::invalid("box", "all values must be finite"));
        }
        if size.iter().any(|&s| s <= 0.0) {
            return Err(AssessError::invalid(
                "box",
                format!(
                    "degenerate box: every side must be > 0 m (got {:.4} x {:.4} x {:.4})",
                    size.x, size.y, size.z
                ),
            ));
        }
        Ok(Self {
            centre,
            half_size: size / 2.0,
            rotation: Rotation3::from_axis_angle(&Vector3::z_axis(), yaw_rad),
        })
    }

    /// The box centre [m].
    pub fn centre(&self) -> Vec3 {
        self.centre
    }

    /// Euclidean distance from `p` to the box [m]; 0 inside or on it.
    pub fn distance(&self, p: &Vec3) -> f64 {
        let local = self.rotation.inverse_transform_vector(&(p - self.centre));
        let outside = Vec3::new(
            (local.x.abs() - self.half_size.x).max(0.0),
            (local.y.abs() - self.half_size.y).max(0.0),
            (local.z.abs() - self.half_size.z).max(0.0),
        );
        outside.norm()
    }

    /// Whether `p` lies inside the box or on its surface.
    pub fn contains(&self, p: &Vec3) -> bool {
        self.distance(p) == 0.0
    }

    /// The eight corners in the workspace frame [m].
    pub fn corners(&self) -> [Vec3; 8] {
        let h = self.half_size;
        let mut out = [Vec3::zeros(); 8];
        for (k, c) in out.iter_mut().enumerate() {
            let s = Vec3::new(
                if k & 1 == 0 { -h.x } else { h.x },
                if k & 2 == 0 { -h.y } else { h.y },
                if k & 4 == 0 { -h.z } else { h.z },
            );
            *c = self.centre + self.rotation * s;
        }
        out
    }
}

/// One calibrated area.
#[derive(Debug, Clone, PartialEq)]
pub struct Area {
    /// Unique name, as in the calibration file.
    pub name: String,
    /// Functional role, if it has one of the four.
    pub role: Option<AreaRole>,
    /// The box.
    pub shape: AreaBox,
    /// Representative centre r_i [m], the target of head and body deviation angles.
    pub representative_centre: Vec3,
}

/// The operator's station: where the operator's torso is while they work, and how far from
/// it a person still counts as being there. Not part of the model's equations: the camera
/// front-end uses it to tell the operator from other people in view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Station {
    position: Vec3,
    radius: f64,
}

impl Station {
    /// Default [`Station::radius`] [m]: about a seated person's reach around their torso.
    pub const DEFAULT_RADIUS_M: f64 = 0.6;

    /// A station at `position` [m] (workspace frame) with `radius` [m].
    ///
    /// Fails when the position is not finite or the radius is not in (0, 5] m.
    pub fn new(position: Vec3, radius: f64) -> Result<Self> {
        if !position.iter().all(|v| v.is_finite()) {
            return Err(AssessError::invalid("station.position_m", "must be finite"));
        }
        if !(radius > 0.0 && radius <= 5.0) {
            return Err(AssessError::invalid(
                "station.radius_m",
                format!("must be in (0, 5] m (got {radius})"),
            ));
        }
        Ok(Self { position, radius })
    }

    /// Where the operator's torso is while they work [m], workspace frame.
    pub fn position(&self) -> Vec3 {
        self.position
    }

    /// How far from [`Station::position`] a person still counts as at the station [m].
    pub fn radius(&self) -> f64 {
        self.radius
    }
}

/// The calibrated workspace: the areas 𝒜, the diagonal D_ws and, optionally, the operator's
/// [`Station`].
#[derive(Debug, Clone, PartialEq)]
pub struct Workspace {
    areas: Vec<Area>,
    diagonal: f64,
    by_role: [Option<AreaId>; 4],
    station: Option<Station>,
}

impl Workspace {
    /// Builds a workspace from areas. `diagonal` is D_ws [m]; `None` takes the diagonal of the
    /// bounding box of all area corners.
    ///
    /// Fails when there is no area, a name repeats, a role appears twice, or D_ws is not > 0.
    pub fn new(areas: Vec<Area>, diagonal: Option<f64>) -> Result<Self> {
        if areas.is_empty() {
            return Err(AssessError::invalid(
                "area",
                "the workspace needs at least one area",
            ));
        }
        let mut by_role = [None; 4];
        for (i, a) in areas.iter().enumerate() {
            if a.name.trim().is_empty() {
                return Err(AssessError::invalid(
                    format!("area[{i}].name"),
                    "must not be empty",
                ));
            }
            if areas[..i].iter().any(|b| b.name == a.name) {
                return Err(AssessError::invalid(
                    format!("area[{i}].name"),
                    format!("names must be unique; `{}` appears twice", a.name),
                ));
            }
            if !a.representative_centre.iter().all(|v| v.is_finite()) {
                return Err(AssessError::invalid(
                    format!("area[{i}].representative_centre_m"),
                    "must be finite",
                ));
            }
            if let Some(role) = a.role {
                let slot = &mut by_role[role_index(role)];
                if slot.is_some() {
                    return Err(AssessError::invalid(
                        format!("area[{i}].role"),
                        format!(
                            "each role may be given to one area only; `{}` repeats",
                            role.short()
                        ),
                    ));
                }
                *slot = Some(AreaId(i));
            }
        }
        let diagonal = match diagonal {
            Some(d) => d,
            None => {
                let mut lo = Vec3::repeat(f64::INFINITY);
                let mut hi = Vec3::repeat(f64::NEG_INFINITY);
                for a in &areas {
                    for c in a.shape.corners() {
                        lo = lo.inf(&c);
                        hi = hi.sup(&c);
                    }
                }
                (hi - lo).norm()
            }
        };
        if !(diagonal.is_finite() && diagonal > 0.0) {
            return Err(AssessError::invalid(
                "diagonal_m",
                format!("D_ws must be finite and > 0 (got {diagonal})"),
            ));
        }
        Ok(Self {
            areas,
            diagonal,
            by_role,
            station: None,
        })
    }

    /// This workspace with the operator's station.
    #[must_use]
    pub fn with_station(mut self, station: Station) -> Self {
        self.station = Some(station);
        self
    }

    /// The operator's station, when the calibration gives one.
    pub fn station(&self) -> Option<&Station> {
        self.station.as_ref()
    }

    /// Loads a calibration TOML file (format in the module docs).
    pub fn from_toml_file(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = crate::error::read_text(path)?;
        Self::from_toml_str_at(&text, path)
    }

    /// Parses a calibration TOML document.
    pub fn from_toml_str(text: &str) -> Result<Self> {
        Self::from_toml_str_at(text, Path::new("<string>"))
    }

    fn from_toml_str_at(text: &str, origin: &Path) -> Result<Self> {
        let raw: RawWorkspace = crate::error::parse_toml(text, origin)?;
        raw.validate()
    }

    /// The areas, in calibration-file order.
    pub fn areas(&self) -> &[Area] {
        &self.areas
    }

    /// One area.
    pub fn area(&self, id: AreaId) -> &Area {
        &self.areas[id.0]
    }

    /// Number of areas N.
    pub fn len(&self) -> usize {
        self.areas.len()
    }

    /// Always false: a workspace has at least one area.
    pub fn is_empty(&self) -> bool {
        self.areas.is_empty()
    }

    /// The workspace diagonal D_ws [m].
    pub fn diagonal(&self) -> f64 {
        self.diagonal
    }

    /// The area that has `role`, if any.
    pub fn by_role(&self, role: AreaRole) -> Option<AreaId> {
        self.by_role[role_index(role)]
    }

    /// The role of area `id`.
    pub fn role(&self, id: AreaId) -> Option<AreaRole> {
        self.areas[id.0].role
    }

    /// The name of a (possibly unassigned) area state: the area's name, or `"none"` for ∅.
    pub fn state_name(&self, state: Option<AreaId>) -> &str {
        state.map_or("none", |id| self.areas[id.0].name.as_str())
    }
}

fn role_index(role: AreaRole) -> usize {
    match role {
        AreaRole::Assembly => 0,
        AreaRole::ToolIdentification => 1,
        AreaRole::Instruction => 2,
        AreaRole::Collaboration => 3,
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWorkspace {
    #[serde(default)]
    diagonal_m: Option<f64>,
    #[serde(default)]
    description: Option<String>,
    #[serde(default)]
    area: Vec<RawArea>,
    #[serde(default)]
    station: Option<RawStation>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStation {
    position_m: [f64; 3],
    #[serde(default)]
    radius_m: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawArea {
    name: String,
    #[serde(default)]
    role: Option<AreaRole>,
    min_m: Option<[f64; 3]>,
    max_m: Option<[f64; 3]>,
    centre_m: Option<[f64; 3]>,
    size_m: Option<[f64; 3]>,
    yaw_deg: Option<f64>,
    representative_centre_m: Option<[f64; 3]>,
}

impl RawWorkspace {
    fn validate(self) -> Result<Workspace> {
        let _ = self.description;
        let mut areas = Vec::with_capacity(self.area.len());
        for (i, a) in self.area.into_iter().enumerate() {
            let key = |k: &str| format!("area[{i}].{k}");
            let shape = match (a.min_m, a.max_m, a.centre_m, a.size_m) {
                (Some(min), Some(max), None, None) => {
                    if a.yaw_deg.is_some() {
                        return Err(AssessError::invalid(
                            key("yaw_deg"),
                            "only allowed with centre_m and size_m",
                        ));
                    }
                    let (min, max) = (Vec3::from(min), Vec3::from(max));
                    if !(min.iter().chain(max.iter()).all(|v| v.is_finite())) {
                        return Err(AssessError::invalid(key("min_m"), "corners must be finite"));
                    }
                    if (0..3).any(|k| min[k] >= max[k]) {
                        return Err(AssessError::invalid(
                            key("max_m"),
                            format!(
                                "degenerate box: max_m must exceed min_m on every axis (min {:?}, max {:?})",
                                <[f64; 3]>::from(min),
                                <[f64; 3]>::from(max)
                            ),
                        ));
                    }
                    AreaBox::from_corners(min, max)?
                }
                (None, None, Some(c), Some(s)) => {
                    let yaw = a.yaw_deg.unwrap_or(0.0);
                    AreaBox::new(Vec3::from(c), Vec3::from(s), yaw.to_radians()).map_err(|e| {
                        match e {
                            AssessError::InvalidValue { rule, .. } => {
                                AssessError::invalid(key("size_m"), rule)
                            }
                            other => other,
                        }
                    })?
                }
                _ => {
                    return Err(AssessError::invalid(
                        key("min_m"),
                        "give either min_m and max_m, or centre_m and size_m (with optional yaw_deg)",
                    ));
                }
            };
            let representative_centre = a
                .representative_centre_m
                .map(Vec3::from)
                .unwrap_or(shape.centre());
            areas.push(Area {
                name: a.name,
                role: a.role,
                shape,
                representative_centre,
            });
        }
        let ws = Workspace::new(areas, self.diagonal_m)?;
        Ok(match self.station {
            Some(st) => ws.with_station(Station::new(
                Vec3::from(st.position_m),
                st.radius_m.unwrap_or(Station::DEFAULT_RADIUS_M),
            )?),
            None => ws,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_to_axis_aligned_box() {
        // Box [0,1]^3. A point at (2, 0.5, 0.5) is 1 m from the face x = 1; (2, 2, 0.5) is
        // sqrt(1^2 + 1^2) = 1.41421356 m from the edge x = 1, y = 1.
        let b = AreaBox::from_corners(Vec3::zeros(), Vec3::repeat(1.0)).unwrap();
        assert_eq!(b.distance(&Vec3::new(0.5, 0.5, 0.5)), 0.0);
        assert!((b.distance(&Vec3::new(2.0, 0.5, 0.5)) - 1.0).abs() < 1e-12);
        assert!((b.distance(&Vec3::new(2.0, 2.0, 0.5)) - 2f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn distance_to_yawed_box() {
        // A 2 x 0.2 x 0.2 box yawed 90°: its long side lies along y. The point (0, 0.9, 0) is
        // inside; (0.5, 0, 0) is 0.5 - 0.1 = 0.4 m from the side face.
        let b = AreaBox::new(
            Vec3::zeros(),
            Vec3::new(2.0, 0.2, 0.2),
            std::f64::consts::FRAC_PI_2,
        )
        .unwrap();
        assert_eq!(b.distance(&Vec3::new(0.0, 0.9, 0.0)), 0.0);
        assert!((b.distance(&Vec3::new(0.5, 0.0, 0.0)) - 0.4).abs() < 1e-12);
    }

    #[test]
    fn loads_and_rejects_calibrations() {
        let ok = r#"
            [[area]]
            name = "a"
            role = "assembly"
            min_m = [0, 0, 0]
            max_m = [1, 1, 1]
            [[area]]
            name = "b"
            centre_m = [3, 0, 0]
            size_m = [1, 1, 1]
            yaw_deg = 45
        "#;
        let ws = Workspace::from_toml_str(ok).unwrap();
        assert_eq!(ws.len(), 2);
        assert_eq!(ws.by_role(AreaRole::Assembly), Some(AreaId(0)));
        // Bounding box of all corners: x from 0 to 3 + sqrt(2)/2, y from -sqrt(2)/2 to 1,
        // z from -0.5 (box b is centred at z = 0) to 1: spans 3.7071, 1.7071, 1.5.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let expect = ((3.0 + h) * (3.0 + h) + (1.0 + h) * (1.0 + h) + 1.5f64 * 1.5).sqrt();
        assert!(
            (ws.diagonal() - expect).abs() < 1e-12,
            "{} vs {expect}",
            ws.diagonal()
        );

        let err = |s: &str| Workspace::from_toml_str(s).unwrap_err().to_string();
        assert!(err("").contains("at least one area"));
        // The operator's station: optional, its radius defaulted and validated.
        assert_eq!(ws.station(), None);
        let area = "[[area]]\nname='a'\nmin_m=[0,0,0]\nmax_m=[1,1,1]\n";
        let with = |st: &str| Workspace::from_toml_str(&format!("{area}[station]\n{st}"));
        let st = *with("position_m=[0.1, -0.2, 1.1]")
            .unwrap()
            .station()
            .unwrap();
        assert_eq!(st.position(), Vec3::new(0.1, -0.2, 1.1));
        assert_eq!(st.radius(), Station::DEFAULT_RADIUS_M);
        let st = *with("position_m=[0,0,1]\nradius_m=0.4")
            .unwrap()
            .station()
            .unwrap();
        assert_eq!(st.radius(), 0.4);
        for bad in ["radius_m=0", "radius_m=-1", "radius_m=5.5", "radius_m=nan"] {
            let e = with(&format!("position_m=[0,0,1]\n{bad}"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("station.radius_m"), "{bad}: {e}");
        }
        let e = with("position_m=[0,inf,1]").unwrap_err().to_string();
        assert!(e.contains("station.position_m"), "{e}");
        let e = with("radius_m=0.5").unwrap_err().to_string();
        assert!(e.contains("position_m"), "{e}");
        let e = err("[[area]]\nname='a'\nmin_m=[0,0,0]\nmax_m=[1,0,1]");
        assert!(
            e.contains("area[0].max_m") && e.contains("degenerate"),
            "{e}"
        );
        let e = err("[[area]]\nname='a'\ncentre_m=[0,0,0]\nsize_m=[1,0,1]");
        assert!(
            e.contains("area[0].size_m") && e.contains("degenerate"),
            "{e}"
        );
        let e = err("[[area]]\nname='a'\nmin_m=[0,0,0]\nmax_m=[1,1,1]\ncolour='red'");
        assert!(e.contains("unknown field") && e.contains("colour"), "{e}");
        let e = err("[[area]]\nname='a'\nrole='col'\nmin_m=[0,0,0]\nmax_m=[1,1,1]");
        assert!(e.contains("unknown variant") && e.contains("col"), "{e}");
        let dup = "[[area]]\nname='a'\nrole='assembly'\nmin_m=[0,0,0]\nmax_m=[1,1,1]\n\
                   [[area]]\nname='b'\nrole='assembly'\nmin_m=[2,0,0]\nmax_m=[3,1,1]";
        assert!(err(dup).contains("area[1].role"));
        let e = err("diagonal_m = 0\n[[area]]\nname='a'\nmin_m=[0,0,0]\nmax_m=[1,1,1]");
        assert!(e.contains("diagonal_m"), "{e}");
    }
}
