//! One camera's perception, frame by frame: landmarks ([`Pipeline`]) → cues in the workspace
//! frame ([`CueExtractor`]), with the intrinsics a user gave for a stream ([`FixedIntrinsics`])
//! and the operator's station ([`Station`]); and the monitoring overlay ([`annotate`]).

use super::cues::{CueConfig, CueExtractor, PerceivedCues, load_canonical_face};
use super::pipeline::{Pipeline, PipelineConfig, StationView};
use super::{CameraFrame, Extrinsics, Intrinsics, Landmarks, RgbImage, draw, models};
use crate::{AreaId, AssessError, Assessment, Result, Station, Workspace};

/// Pinhole intrinsics without an image size, as a user gives them for a camera (`fx,fy,cx,cy`
/// [px]); [`Self::at_size`] makes them [`Intrinsics`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    /// Focal length along x [px].
    pub fx: f64,
    /// Focal length along y [px].
    pub fy: f64,
    /// Principal point x [px].
    pub cx: f64,
    /// Principal point y [px].
    pub cy: f64,
}

impl Pinhole {
    /// As [`Intrinsics`] of a `width` × `height` image [px].
    pub fn at_size(self, width: u32, height: u32) -> Intrinsics {
        Intrinsics {
            width,
            height,
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
        }
    }
}

/// [`Pinhole`] intrinsics applied to the frames of one source: they hold for one camera, so
/// the first frame fixes the image size and a frame of another size is an error.
#[derive(Debug, Clone, Copy)]
pub struct FixedIntrinsics {
    pinhole: Pinhole,
    /// The first frame's size (width, height) [px].
    size: Option<(u32, u32)>,
}

impl FixedIntrinsics {
    /// Nothing seen yet.
    pub fn new(pinhole: Pinhole) -> Self {
        Self {
            pinhole,
            size: None,
        }
    }

    /// The intrinsics of frame `index`, an image of `width` × `height` [px];
    /// [`AssessError::InvalidValue`] (key `intrinsics`) when the size is not the first frame's.
    pub fn at(&mut self, index: u64, width: u32, height: u32) -> Result<Intrinsics> {
        match *self.size.get_or_insert((width, height)) {
            (w, h) if (w, h) == (width, height) => Ok(self.pinhole.at_size(width, height)),
            (w, h) => Err(AssessError::invalid(
                "intrinsics",
                format!(
                    "frame {index} is {width} x {height} px but the first frame was {w} x {h} \
                     px: given intrinsics hold for one camera (without them, each image of a \
                     folder gets intrinsics from the field of view for its own size)"
                ),
            )),
        }
    }
}

/// Landmarks → cues for one camera: the landmark [`Pipeline`] and the [`CueExtractor`].
#[derive(Debug)]
pub struct Perception {
    pipeline: Pipeline,
    extractor: CueExtractor,
    intrinsics: Option<FixedIntrinsics>,
    /// The operator's station (workspace frame).
    station: Option<Station>,
}

/// One frame's perception result.
#[derive(Debug)]
pub struct Perceived {
    /// The landmarks [px].
    pub landmarks: Landmarks,
    /// The cues (workspace frame) and their quality.
    pub cues: PerceivedCues,
    /// The intrinsics used.
    pub intrinsics: Intrinsics,
}

impl Perception {
    /// Initialises ONNX Runtime ([`models::init_runtime`]), loads the models from
    /// [`models::model_dir`] and the canonical face. `intrinsics` overrides the frames' own
    /// (for video files, image folders and webcams; see [`FixedIntrinsics`]). `station` (the
    /// workspace's) makes a person there the preferred operator
    /// ([`super::pipeline::rank_operators`]).
    pub fn load(
        config: PipelineConfig,
        extrinsics: Extrinsics,
        intrinsics: Option<Pinhole>,
        station: Option<&Station>,
    ) -> Result<Self> {
        models::init_runtime(None)?;
        let dir = models::model_dir();
        let pipeline = Pipeline::load(&dir, config)?;
        let canonical = load_canonical_face(&dir.join("canonical_face_model.csv"))?;
        let extractor = CueExtractor::new(CueConfig::default(), extrinsics, canonical)?;
        Ok(Self {
            pipeline,
            extractor,
            intrinsics: intrinsics.map(FixedIntrinsics::new),
            station: station.copied(),
        })
    }

    /// Landmarks and cues of one frame (cue time = camera time). With given intrinsics, a
    /// frame whose size differs from the first is an error; a failure is
    /// [`AssessError::Frame`] naming the frame.
    pub fn step(&mut self, frame: &CameraFrame) -> Result<Perceived> {
        let in_frame = |source| AssessError::Frame {
            index: frame.index,
            source: Box::new(source),
        };
        let intrinsics = match &mut self.intrinsics {
            Some(fixed) => fixed
                .at(frame.index, frame.color.width, frame.color.height)
                .map_err(in_frame)?,
            None => frame.intrinsics,
        };
        let station = self.station.as_ref().and_then(|st| {
            StationView::from_workspace(st, self.extractor.extrinsics(), intrinsics)
        });
        self.pipeline.set_station(station);
        let landmarks = self
            .pipeline
            .process_at(frame.t, &frame.color, frame.depth.as_ref())
            .map_err(in_frame)?;
        let cues = self
            .extractor
            .extract(frame.t, &landmarks, frame.depth.as_ref(), &intrinsics);
        Ok(Perceived {
            landmarks,
            cues,
            intrinsics,
        })
    }

    /// The extrinsics in use.
    pub fn extrinsics(&self) -> &Extrinsics {
        self.extractor.extrinsics()
    }

    /// The landmark pipeline (for its stage times and run counts).
    pub fn pipeline(&self) -> &Pipeline {
        &self.pipeline
    }
}

/// Draws the monitoring view on a copy of the frame: landmarks, the workspace areas projected
/// with `extrinsics` (the confirmed area highlighted), the head ray and, given an assessment,
/// the live indicator values.
pub fn annotate(
    frame: &CameraFrame,
    p: &Perceived,
    extrinsics: &Extrinsics,
    workspace: &Workspace,
    a: Option<&Assessment>,
) -> Result<RgbImage> {
    let mut img = frame.color.clone();
    let proj = draw::Projector::new(p.intrinsics, extrinsics);
    draw::areas(&mut img, &proj, workspace, a.and_then(|a| a.confirmed))?;
    draw::landmarks(&mut img, &p.landmarks)?;
    if let Some(head) = &p.cues.frame.head {
        draw::head_ray(&mut img, &proj, &head.position, &head.facing, 0.8)?;
    }
    let name = |id: Option<AreaId>| {
        id.and_then(|i| workspace.areas().get(i.0))
            .map_or("none", |a| a.name.as_str())
    };
    let mut lines = vec![format!(
        "t {:.3} s  frame {}  cues: {}",
        frame.t,
        frame.index,
        p.cues.quality.name()
    )];
    if let Some(a) = a {
        let w = &a.windowed;
        lines.push(format!(
            "F {}  (perceptual {}, action {})",
            name(a.confirmed),
            name(a.perceptual.0),
            name(a.action.0)
        ));
        lines.push(format!(
            "AED {:.2}  TID {:.2}  ICD {:.2}  ASD {:.2}/s  OHD {:.2}",
            w.aed, w.tid, w.icd, w.asd_ctx, w.ohd
        ));
        lines.push(format!(
            "HRC-CWL {:.2} ({})  dominant {}",
            w.hrc_cwl,
            w.category.name(),
            a.dominant.indicator.map_or("none", |i| i.name())
        ));
    }
    draw::text_lines(&mut img, &lines, draw::WHITE)?;
    Ok(img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_intrinsics_take_the_frame_size_and_refuse_another() {
        let pinhole = Pinhole {
            fx: 600.0,
            fy: 610.0,
            cx: 320.0,
            cy: 240.0,
        };
        let mut fixed = FixedIntrinsics::new(pinhole);
        let k = fixed.at(0, 640, 480).unwrap();
        assert_eq!(
            (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
            (640, 480, 600.0, 610.0, 320.0, 240.0)
        );
        assert_eq!(fixed.at(1, 640, 480).unwrap(), k);
        let e = fixed.at(2, 320, 240).unwrap_err().to_string();
        assert!(
            e.contains("frame 2 is 320 x 240 px but the first frame was 640 x 480 px"),
            "{e}"
        );
    }
}
