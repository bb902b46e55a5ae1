//! The indicator-dynamics figure, in the style of the paper's: four panels over time,
//! (a) AED, TID, ICD; (b) ASD_ctx; (c) OHD with the C(t) = 1 periods shaded; (d) HRC-CWL over its
//! low/medium/high category bands. Each panel is written as its own PNG, and all four as one
//! 2 × 2 figure.
//!
//! Text uses the DejaVu Sans font embedded in the binary, so no system font is needed.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::chart::SeriesAnno;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::Sample;

/// The font family name the embedded font is registered under.
pub(crate) const FAMILY: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// Pixel size of one panel PNG (width, height).
const PANEL_PX: (u32, u32) = (1000, 460);
/// Pixel size of the combined 2 × 2 figure.
const FIGURE_PX: (u32, u32) = (2000, 920);

// A colour-blind-safe palette (Okabe–Ito).
pub(crate) const BLUE: RGBColor = RGBColor(0, 114, 178);
pub(crate) const ORANGE: RGBColor = RGBColor(230, 159, 0);
pub(crate) const GREEN: RGBColor = RGBColor(0, 158, 115);
pub(crate) const VERMILION: RGBColor = RGBColor(213, 94, 0);
pub(crate) const PURPLE: RGBColor = RGBColor(204, 121, 167);
pub(crate) const SKY: RGBColor = RGBColor(86, 180, 233);
const GREY: RGBColor = RGBColor(120, 120, 120);

/// Everything the figure shows.
#[derive(Debug)]
pub(crate) struct Figure<'a> {
    /// The assessed frames, in time order.
    pub(crate) samples: &'a [Sample],
    /// HRC-CWL at which the category becomes medium [-].
    pub(crate) medium_from: f64,
    /// HRC-CWL at which the category becomes high [-].
    pub(crate) high_from: f64,
    /// The sliding horizon of the windowed indicators [s] (for the legend).
    pub(crate) horizon_s: f64,
}

/// The files [`render`] writes, relative to its folder, in panel order, then the combined figure.
pub(crate) const FILES: [&str; 5] = [
    "indicators_a_area_demand.png",
    "indicators_b_asd_ctx.png",
    "indicators_c_ohd.png",
    "indicators_d_hrc_cwl.png",
    "indicator_dynamics.png",
];

/// Registers the embedded font (once per process).
pub(crate) fn register_font() -> crate::Result<()> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, FONT_BYTES).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(crate::Error::data(
            "the embedded font assets/fonts/DejaVuSans.ttf",
            "could not be loaded",
        ))
    }
}

/// Renders the four panels and the combined figure into `dir`; returns the paths written.
pub(crate) fn render(dir: &Path, fig: &Figure<'_>) -> crate::Result<Vec<PathBuf>> {
    register_font()?;
    if fig.samples.is_empty() {
        return Err(crate::Error::data("nothing to plot", "no assessed frame"));
    }
    let mut written = Vec::with_capacity(FILES.len());
    for (k, name) in FILES[..4].iter().enumerate() {
        let path = dir.join(name);
        {
            let root = BitMapBackend::new(&path, PANEL_PX).into_drawing_area();
            panel(k, &root, fig).map_err(|e| plot_error(&path, &e))?;
            root.present().map_err(|e| plot_error(&path, &e))?;
        }
        written.push(path);
    }
    let path = dir.join(FILES[4]);
    {
        let root = BitMapBackend::new(&path, FIGURE_PX).into_drawing_area();
        let cells = root.split_evenly((2, 2));
        for (k, cell) in cells.iter().enumerate() {
            panel(k, cell, fig).map_err(|e| plot_error(&path, &e))?;
        }
        root.present().map_err(|e| plot_error(&path, &e))?;
    }
    written.push(path);
    for p in &written {
        std::fs::metadata(p).map_err(crate::Error::io("find the plot just written", p))?;
    }
    Ok(written)
}

/// The [`crate::Error::Plot`] of drawing `path`.
fn plot_error(path: &Path, e: &dyn std::fmt::Display) -> crate::Error {
    crate::Error::Plot {
        path: path.to_path_buf(),
        reason: e.to_string(),
    }
}

type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// Draws panel `k` (0 = (a) … 3 = (d)) into `area`.
fn panel<DB: DrawingBackend>(
    k: usize,
    area: &DrawingArea<DB, Shift>,
    fig: &Figure<'_>,
) -> DrawResult<DB> {
    match k {
        0 => panel_a(area, fig),
        1 => panel_b(area, fig),
        2 => panel_c(area, fig),
        _ => panel_d(area, fig),
    }
}

/// The embedded font at `size` [px], black.
pub(crate) fn font(size: u32) -> TextStyle<'static> {
    (FAMILY, size).into_font().color(&BLACK)
}

/// The time axis range [s]; a single frame gets a 1 s axis.
fn time_range(fig: &Figure<'_>) -> std::ops::Range<f64> {
    let t0 = fig.samples.first().map_or(0.0, |s| s.t);
    let t1 = fig.samples.last().map_or(1.0, |s| s.t);
    if t1 > t0 { t0..t1 } else { t0..t0 + 1.0 }
}

/// An upper y limit with headroom, never below `floor`.
fn y_max(values: impl Iterator<Item = f64>, floor: f64) -> f64 {
    let m = values.filter(|v| v.is_finite()).fold(0.0_f64, f64::max);
    (m * 1.12).max(floor)
}

/// The time intervals [start, end) [s] over which `flag` holds. A flagged frame k stands for the
/// interval up to the next frame.
fn intervals(samples: &[Sample], flag: impl Fn(&Sample) -> bool) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut start: Option<f64> = None;
    for s in samples {
        match (flag(s), start) {
            (true, None) => start = Some(s.t),
            (false, Some(a)) => {
                out.push((a, s.t));
                start = None;
            }
            _ => {}
        }
    }
    if let (Some(a), Some(last)) = (start, samples.last()) {
        out.push((a, last.t));
    }
    out
}

type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Draws a polyline as separate segments after merging points that fall on the same pixel.
///
/// plotters joins the segments of a thick polyline with mitre joins, which shoot out spikes
/// wherever a dense series turns back on itself within a pixel (the stepwise rises and decays of
/// the cumulative indicators do this constantly). Unjoined segments with a dot at each vertex
/// draw the same line without the spikes. Returns the segments' series, for its legend entry.
fn draw_line<'a, 'b, DB: DrawingBackend + 'a>(
    chart: &'b mut Chart<'a, DB>,
    points: impl Iterator<Item = (f64, f64)>,
    style: ShapeStyle,
) -> Result<&'b mut SeriesAnno<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let mut kept: Vec<(f64, f64)> = Vec::new();
    let mut last_px = None;
    let mut pending = None;
    for p in points.filter(|p| p.0.is_finite() && p.1.is_finite()) {
        let px = chart.backend_coord(&p);
        if last_px == Some(px) {
            pending = Some(p);
            continue;
        }
        kept.push(p);
        last_px = Some(px);
        pending = None;
    }
    kept.extend(pending);
    if style.stroke_width > 1 {
        let r = style.stroke_width / 2;
        chart.draw_series(
            kept.iter()
                .map(|&p| Circle::new(p, r, style.color.filled())),
        )?;
    }
    chart.draw_series(
        kept.windows(2)
            .map(|w| PathElement::new(vec![w[0], w[1]], style)),
    )
}

/// Common frame: caption, margins, axes with units, a light grid.
fn chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
    y_desc: &str,
) -> Result<Chart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    area.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(area)
        .caption(caption, font(24))
        .margin_top(10)
        .margin_left(14)
        .margin_right(28)
        .margin_bottom(8)
        .x_label_area_size(56)
        .y_label_area_size(78)
        .build_cartesian_2d(x, y)?;
    chart
        .configure_mesh()
        .x_desc("time t [s]")
        .y_desc(y_desc)
        .axis_desc_style(font(19))
        .label_style(font(16))
        .x_labels(10)
        .y_labels(6)
        .light_line_style(TRANSPARENT)
        .bold_line_style(BLACK.mix(0.07))
        .axis_style(BLACK.mix(0.8))
        .x_label_formatter(&|v| trim_number(*v))
        .y_label_formatter(&|v| trim_number(*v))
        .draw()?;
    Ok(chart)
}

/// An axis tick label: up to 3 decimals, without trailing zeros.
fn trim_number(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

fn line_style(c: RGBColor, width: u32) -> ShapeStyle {
    ShapeStyle {
        color: c.to_rgba(),
        filled: false,
        stroke_width: width,
    }
}

fn legend_line(c: RGBColor, width: u32) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], line_style(c, width))
}

fn legend_box(c: RGBAColor) -> impl Fn((i32, i32)) -> Rectangle<(i32, i32)> {
    move |(x, y)| Rectangle::new([(x, y - 7), (x + 24, y + 7)], c.filled())
}

/// Draws the legend in the place, of eight around the plot's edges, that covers the fewest of
/// `points` (data coordinates; ties go to the earlier place, upper right first).
fn draw_legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    labels: &[&str],
    points: impl Iterator<Item = (f64, f64)>,
) -> DrawResult<DB> {
    use SeriesLabelPosition::*;
    const MARGIN: i32 = 12;
    const KEY: i32 = 30;
    let style = font(16);
    let text_w = labels
        .iter()
        .map(|l| {
            style
                .font
                .box_size(l)
                .map_or(10 * l.len() as i32, |(w, _)| w as i32)
        })
        .max()
        .unwrap_or(0);
    // The legend box as plotters lays it out (text lines ≈ 1.3 × the font size apart).
    let (w, h) = (
        text_w + KEY + 2 * MARGIN,
        (labels.len() as i32 * 21) + 2 * MARGIN,
    );
    let (xr, yr) = chart.plotting_area().get_pixel_range();
    let (aw, ah) = (xr.end - xr.start, yr.end - yr.start);
    let candidates = [
        UpperRight,
        UpperLeft,
        UpperMiddle,
        LowerRight,
        LowerLeft,
        LowerMiddle,
        MiddleRight,
        MiddleLeft,
    ];
    let origin = |p: &SeriesLabelPosition| {
        let x = match p {
            UpperLeft | MiddleLeft | LowerLeft => 5,
            UpperMiddle | LowerMiddle => (aw - w) / 2,
            _ => aw - w - 5,
        };
        let y = match p {
            UpperLeft | UpperMiddle | UpperRight => 5,
            MiddleLeft | MiddleRight => (ah - h) / 2,
            _ => ah - h - 5,
        };
        (x + xr.start, y + yr.start)
    };
    let mut covered = [0usize; 8];
    for p in points {
        let (px, py) = chart.backend_coord(&p);
        for (n, c) in covered.iter_mut().zip(&candidates) {
            let (x0, y0) = origin(c);
            if (x0..=x0 + w).contains(&px) && (y0..=y0 + h).contains(&py) {
                *n += 1;
            }
        }
    }
    let best = (0..candidates.len())
        .min_by_key(|&i| (covered[i], i))
        .unwrap_or(0);
    chart
        .configure_series_labels()
        .position(candidates[best].clone())
        .margin(MARGIN as u32)
        .legend_area_size(KEY as u32)
        .label_font(style)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK.mix(0.35))
        .draw()
}

/// (a) AED, TID and ICD over time.
fn panel_a<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, fig: &Figure<'_>) -> DrawResult<DB> {
    let mut chart = chart(
        area,
        "(a) Area demand: AED, TID, ICD",
        time_range(fig),
        0.0..1.0,
        "demand D [-]",
    )?;
    for (k, (name, colour)) in [("AED", BLUE), ("TID", ORANGE), ("ICD", GREEN)]
        .into_iter()
        .enumerate()
    {
        draw_line(
            &mut chart,
            fig.samples.iter().map(|s| (s.t, s.demand[k])),
            line_style(colour, 3),
        )?
        .label(name)
        .legend(legend_line(colour, 3));
    }
    let points = fig.samples.iter().flat_map(|s| s.demand.map(|d| (s.t, d)));
    draw_legend(&mut chart, &["AED", "TID", "ICD"], points)
}

/// (b) ASD_ctx over time.
fn panel_b<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, fig: &Figure<'_>) -> DrawResult<DB> {
    let top = y_max(fig.samples.iter().map(|s| s.asd_ctx), 0.1);
    let mut chart = chart(
        area,
        "(b) Context-aware attention switching: ASD_ctx",
        time_range(fig),
        0.0..top,
        "ASD_ctx [weighted switches/s]",
    )?;
    draw_line(
        &mut chart,
        fig.samples.iter().map(|s| (s.t, s.asd_ctx)),
        line_style(VERMILION, 3),
    )?
    .label("ASD_ctx")
    .legend(legend_line(VERMILION, 3));
    draw_legend(
        &mut chart,
        &["ASD_ctx"],
        fig.samples.iter().map(|s| (s.t, s.asd_ctx)),
    )
}

/// (c) OHD over time, with C(t) = 1 (and H(t) = 1) shaded.
fn panel_c<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, fig: &Figure<'_>) -> DrawResult<DB> {
    let top = y_max(fig.samples.iter().map(|s| s.ohd), 0.1).min(1.0);
    let mut chart = chart(
        area,
        "(c) Operation hesitation: OHD",
        time_range(fig),
        0.0..top,
        "OHD [-]",
    )?;
    let collab = SKY.mix(0.22);
    let hes = PURPLE.mix(0.35);
    chart
        .draw_series(
            intervals(fig.samples, |s| s.collaborating)
                .into_iter()
                .map(|(a, b)| Rectangle::new([(a, 0.0), (b, top)], collab.filled())),
        )?
        .label("C(t) = 1 (collaboration)")
        .legend(legend_box(collab));
    chart
        .draw_series(
            intervals(fig.samples, |s| s.hesitating)
                .into_iter()
                .map(|(a, b)| Rectangle::new([(a, 0.0), (b, top * 0.06)], hes.filled())),
        )?
        .label("H(t) = 1 (hesitation)")
        .legend(legend_box(hes));
    draw_line(
        &mut chart,
        fig.samples.iter().map(|s| (s.t, s.ohd)),
        line_style(PURPLE, 3),
    )?
    .label("OHD")
    .legend(legend_line(PURPLE, 3));
    // The hesitation strip lies along the bottom; the legend should not hide it either.
    let points = fig.samples.iter().flat_map(|s| {
        let strip = s.hesitating.then_some((s.t, top * 0.03));
        std::iter::once((s.t, s.ohd)).chain(strip)
    });
    let labels = ["C(t) = 1 (collaboration)", "H(t) = 1 (hesitation)", "OHD"];
    draw_legend(&mut chart, &labels, points)
}

/// (d) HRC-CWL over its category bands.
fn panel_d<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, fig: &Figure<'_>) -> DrawResult<DB> {
    let x = time_range(fig);
    let mut chart = chart(
        area,
        "(d) Composite workload: HRC-CWL",
        x.clone(),
        0.0..1.0,
        "HRC-CWL [-]",
    )?;
    let bands = [
        ("low", 0.0, fig.medium_from, GREEN),
        ("medium", fig.medium_from, fig.high_from, ORANGE),
        ("high", fig.high_from, 1.0, VERMILION),
    ];
    chart.draw_series(bands.iter().map(|&(_, lo, hi, c)| {
        Rectangle::new([(x.start, lo), (x.end, hi)], c.mix(0.13).filled())
    }))?;
    let windowed = format!("windowed ({} s)", trim_number(fig.horizon_s));
    let label_x = x.end - (x.end - x.start) * 0.008;
    let anchor = Pos::new(HPos::Right, VPos::Center);
    chart.draw_series(bands.iter().map(|&(name, lo, hi, c)| {
        Text::new(
            name,
            (label_x, (lo + hi) / 2.0),
            (FAMILY, 17).into_font().color(&c).pos(anchor),
        )
    }))?;
    draw_line(
        &mut chart,
        fig.samples.iter().map(|s| (s.t, s.hrc_cwl_windowed)),
        line_style(GREY, 2),
    )?
    .label(&windowed)
    .legend(legend_line(GREY, 2));
    draw_line(
        &mut chart,
        fig.samples.iter().map(|s| (s.t, s.hrc_cwl)),
        line_style(BLACK, 3),
    )?
    .label("HRC-CWL (cumulative)")
    .legend(legend_line(BLACK, 3));
    // Neither the lines nor the band names at the right edge should be hidden.
    let names = bands
        .iter()
        .map(|&(_, lo, hi, _)| (label_x, (lo + hi) / 2.0));
    let points = fig
        .samples
        .iter()
        .flat_map(|s| [(s.t, s.hrc_cwl), (s.t, s.hrc_cwl_windowed)]);
    let points = points.chain(names.clone().cycle().take(3 * 50));
    draw_legend(&mut chart, &[&windowed, "HRC-CWL (cumulative)"], points)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t: f64, collaborating: bool) -> Sample {
        Sample {
            t,
            demand: [0.5, 0.2, 0.1],
            asd_ctx: 0.3,
            ohd: 0.1,
            hrc_cwl: 0.4,
            hrc_cwl_windowed: 0.45,
            collaborating,
            hesitating: false,
        }
    }

    #[test]
    fn flagged_runs_become_intervals() {
        let flags = [false, true, true, false, true];
        let s: Vec<Sample> = flags
            .iter()
            .enumerate()
            .map(|(k, &c)| sample(k as f64 * 0.5, c))
            .collect();
        // Frames 1–2 hold until frame 3 (1.5 s); frame 4 is the last, so its run ends at 2.0 s.
        assert_eq!(
            intervals(&s, |s| s.collaborating),
            vec![(0.5, 1.5), (2.0, 2.0)]
        );
        assert!(intervals(&s, |s| s.hesitating).is_empty());
    }

    #[test]
    fn tick_labels_drop_trailing_zeros() {
        assert_eq!(trim_number(2.0), "2");
        assert_eq!(trim_number(0.25), "0.25");
        assert_eq!(trim_number(-0.0001), "0");
        assert_eq!(trim_number(1.23456), "1.235");
    }

    #[test]
    fn renders_five_pngs() {
        let dir = tempfile::tempdir().unwrap();
        let samples: Vec<Sample> = (0..300)
            .map(|k| sample(k as f64 / 30.0, (100..200).contains(&k)))
            .collect();
        let fig = Figure {
            samples: &samples,
            medium_from: 0.33,
            high_from: 0.66,
            horizon_s: 30.0,
        };
        let written = render(dir.path(), &fig).unwrap();
        assert_eq!(written.len(), 5);
        for (path, name) in written.iter().zip(FILES) {
            assert_eq!(path.file_name().unwrap(), name);
            let bytes = std::fs::read(path).unwrap();
            assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name} is not a PNG");
            // IHDR: width and height, big-endian, at bytes 16..24.
            let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
            let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
            let want = if name == FILES[4] {
                FIGURE_PX
            } else {
                PANEL_PX
            };
            assert_eq!((w, h), want, "{name}");
        }
    }
}
