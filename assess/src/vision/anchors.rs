//! SSD anchors, as MediaPipe's `SsdAnchorsCalculator` generates them for its BlazeFace-style
//! detectors (fixed anchor size, aspect ratio 1, one interpolated scale per layer).

/// The anchor options of one detector (MediaPipe's `SsdAnchorsCalculatorOptions`, the subset
/// the pose, palm and face detectors use).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct AnchorOptions {
    /// Model input width [px].
    pub input_width: u32,
    /// Model input height [px].
    pub input_height: u32,
    /// Smallest anchor scale [-].
    pub min_scale: f32,
    /// Largest anchor scale [-].
    pub max_scale: f32,
    /// Anchor centre offset within a feature-map cell [-].
    pub offset: f32,
    /// Stride of each layer [px]; consecutive equal strides share a feature map.
    pub strides: &'static [u32],
}

/// One anchor centre, normalised to the model input [-]. (Anchor width and height are 1: the
/// detectors use fixed-size anchors.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Anchor {
    /// Centre x [-].
    pub cx: f32,
    /// Centre y [-].
    pub cy: f32,
}

/// pose_detection: 224 × 224, 2254 anchors.
pub(crate) const POSE_DETECTION: AnchorOptions = AnchorOptions {
    input_width: 224,
    input_height: 224,
    min_scale: 0.148_437_5,
    max_scale: 0.75,
    offset: 0.5,
    strides: &[8, 16, 32, 32, 32],
};

/// palm_detection (full and lite): 192 × 192, 2016 anchors.
pub(crate) const PALM_DETECTION: AnchorOptions = AnchorOptions {
    input_width: 192,
    input_height: 192,
    min_scale: 0.148_437_5,
    max_scale: 0.75,
    offset: 0.5,
    strides: &[8, 16, 16, 16],
};

/// face_detection_short_range: 128 × 128, 896 anchors.
pub(crate) const FACE_DETECTION: AnchorOptions = AnchorOptions {
    input_width: 128,
    input_height: 128,
    min_scale: 0.148_437_5,
    max_scale: 0.75,
    offset: 0.5,
    strides: &[8, 16, 16, 16],
};

/// Generates the anchors in MediaPipe's order: layer by layer (equal strides merged), row by
/// row, column by column, and per cell one anchor per scale: with aspect ratio 1 and the
/// interpolated scale that is two anchors per layer of the merged group.
pub(crate) fn generate(options: &AnchorOptions) -> Vec<Anchor> {
    let strides = options.strides;
    let mut anchors = Vec::new();
    let mut layer = 0;
    while layer < strides.len() {
        // Layers with the same stride share one feature map; each adds two anchors per cell
        // (its own scale and the interpolated one). With fixed anchor sizes only the count
        // matters.
        let mut last = layer;
        let mut per_cell = 0;
        while last < strides.len() && strides[last] == strides[layer] {
            per_cell += 2;
            last += 1;
        }
        let stride = strides[layer] as f32;
        let rows = (options.input_height as f32 / stride).ceil() as u32;
        let cols = (options.input_width as f32 / stride).ceil() as u32;
        for y in 0..rows {
            for x in 0..cols {
                let anchor = Anchor {
                    cx: (x as f32 + options.offset) / cols as f32,
                    cy: (y as f32 + options.offset) / rows as f32,
                };
                anchors.extend(std::iter::repeat_n(anchor, per_cell));
            }
        }
        layer = last;
    }
    anchors
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anchor_counts_match_the_models_box_counts() {
        // Hand count: pose 28²·2 + 14²·2 + 7²·6 = 1568 + 392 + 294 = 2254;
        // palm 24²·2 + 12²·6 = 1152 + 864 = 2016; face 16²·2 + 8²·6 = 512 + 384 = 896.
        assert_eq!(generate(&POSE_DETECTION).len(), 2254);
        assert_eq!(generate(&PALM_DETECTION).len(), 2016);
        assert_eq!(generate(&FACE_DETECTION).len(), 896);
    }

    #[test]
    fn first_and_last_anchors_are_cell_centres() {
        let a = generate(&FACE_DETECTION);
        // First layer: 16 × 16 cells, first cell centre (0.5/16, 0.5/16), two anchors.
        assert_eq!(
            a[0],
            Anchor {
                cx: 0.5 / 16.0,
                cy: 0.5 / 16.0
            }
        );
        assert_eq!(a[1], a[0]);
        assert_eq!(a[2].cx, 1.5 / 16.0);
        // Last merged layer: 8 × 8 cells, last cell centre (7.5/8, 7.5/8).
        assert_eq!(
            a[895],
            Anchor {
                cx: 7.5 / 8.0,
                cy: 7.5 / 8.0
            }
        );
        // The second layer starts after 512 anchors with 6 per cell.
        assert_eq!(
            a[512],
            Anchor {
                cx: 0.5 / 8.0,
                cy: 0.5 / 8.0
            }
        );
        assert_eq!(a[517], a[512]);
        assert_eq!(a[518].cx, 1.5 / 8.0);
    }
}
