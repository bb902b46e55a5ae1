//! `report.html`: one self-contained page per trial (the PNG plots are embedded as base64 data
//! URIs and also left next to it as files).
//!
//! Plots (time axis: trial time [s]):
//! - `report_indicators.png`: the windowed normalised indicators (AED, TID, ICD, ASD̃, OHD) with
//!   the reported dominant indicator as a coloured band above them;
//! - `indicator_dynamics.png` (and its four panels): the `hrc-adapt assess` figure, from
//!   `report::plot`;
//! - `report_adaptation.png`: speed, acceleration and jerk scales; start delay and minimum
//!   approach duration;
//! - `report_robot.png`: TCP speed and the minimum human distance;
//! - `report_handovers.png`: the handover timeline: task phases as bars, operator idle and
//!   (simulated) hesitation as bars, Presented/Grasped/returned markers per handover;
//! - `report_motion.png`: motion quality: TCP speed with the stop windows shaded (separation
//!   windows in vermilion, others in grey) and the stop-and-go events outside stops marked;
//!   the executed jerk (largest |j| over the joints per 10 ms, log scale) against 1.1 × the
//!   planner's jerk limit; the planner's time scale.
//!
//! The page's "Motion quality" section tabulates `summary.json`'s `motion` object (README.md,
//! "Motion quality metrics").
//!
//! A simulated trial is labelled SIMULATED in the page title, a banner, and every plot caption.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::Error;
use assess::Indicator;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::events::TrialEvent;
use super::log::summary::Summary;
use super::log::{LogOptions, Recorded, TrialMeta};
use crate::report::plot::{BLUE, GREEN, ORANGE, PURPLE, SKY, VERMILION, font, register_font};
use assess_report::plot;

/// The `hrc-adapt assess` outputs (`src/report`: the indicator table and figure), shared with
/// `hrc-adapt assess`.
pub(crate) use crate::report as assess_report;

/// What [`write()`] left.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ReportFiles {
    /// `report.html`.
    pub(crate) html: PathBuf,
    /// Every PNG written.
    pub(crate) plots: Vec<PathBuf>,
}

/// The page.
pub(crate) const HTML_FILE: &str = "report.html";
/// The dominant-indicator plot.
pub(crate) const INDICATORS_PNG: &str = "report_indicators.png";
/// The adaptation plot.
pub(crate) const ADAPTATION_PNG: &str = "report_adaptation.png";
/// The robot speed / human distance plot.
pub(crate) const ROBOT_PNG: &str = "report_robot.png";
/// The handover timeline.
pub(crate) const HANDOVERS_PNG: &str = "report_handovers.png";
/// The motion-quality plot.
pub(crate) const MOTION_PNG: &str = "report_motion.png";
/// At most this many stop windows are tabulated in the page (all are in `summary.json`).
const WINDOW_ROWS: usize = 100;

const PX: (u32, u32) = (1400, 560);

// Okabe–Ito, shared with `report::plot` (plus yellow and a lighter grey here).
const YELLOW: RGBColor = RGBColor(240, 228, 66);
const GREY: RGBColor = RGBColor(150, 150, 150);

/// Colour of an indicator (and of "none").
fn indicator_colour(k: Option<Indicator>) -> RGBColor {
    match k {
        Some(Indicator::Aed) => BLUE,
        Some(Indicator::Tid) => ORANGE,
        Some(Indicator::Icd) => GREEN,
        Some(Indicator::AsdCtx) => VERMILION,
        Some(Indicator::Ohd) => PURPLE,
        None => RGBColor(215, 215, 215),
    }
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;
type Chart<'a, 'b> = ChartContext<
    'a,
    BitMapBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;
type Res<T> =
    Result<T, DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>>;

/// A plotting failure's message (the caller names the file: [`Error::Plot`]).
fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// What the `plot_*` functions return: the plotting library's message on a failure.
type PlotResult = Result<(), String>;

/// The [`Error::Plot`] of drawing `path`.
fn plot_error(path: &Path) -> impl FnOnce(String) -> Error {
    let path = path.to_path_buf();
    move |reason| Error::Plot { path, reason }
}

/// A chart with a time axis, caption, units and a light grid.
fn chart<'a, 'b>(
    area: &'a Area<'b>,
    caption: &str,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
    y_desc: &str,
    top_margin: u32,
) -> Res<Chart<'a, 'b>> {
    let mut c = ChartBuilder::on(area)
        .caption(caption, font(22))
        .margin_top(top_margin)
        .margin_left(14)
        .margin_right(24)
        .margin_bottom(6)
        .x_label_area_size(46)
        .y_label_area_size(80)
        .build_cartesian_2d(x, y)?;
    c.configure_mesh()
        .x_desc("trial time t [s]")
        .y_desc(y_desc)
        .axis_desc_style(font(18))
        .label_style(font(15))
        .x_labels(12)
        .y_labels(6)
        .light_line_style(TRANSPARENT)
        .bold_line_style(BLACK.mix(0.08))
        .draw()?;
    Ok(c)
}

fn style(c: RGBColor, w: u32) -> ShapeStyle {
    ShapeStyle {
        color: c.to_rgba(),
        filled: false,
        stroke_width: w,
    }
}

/// A step series: value holds until the next sample.
fn steps(points: &[(f64, f64)], t_end: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(points.len() * 2 + 1);
    for (k, &(t, v)) in points.iter().enumerate() {
        if k > 0 {
            out.push((t, points[k - 1].1));
        }
        out.push((t, v));
    }
    if let Some(&(_, v)) = points.last() {
        out.push((t_end, v));
    }
    out
}

fn draw_series<'a, 'b: 'a>(
    c: &mut Chart<'a, 'b>,
    points: Vec<(f64, f64)>,
    colour: RGBColor,
    width: u32,
    label: &str,
) -> Res<()> {
    let pts: Vec<(f64, f64)> = points
        .into_iter()
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    c.draw_series(LineSeries::new(pts, style(colour, width)))?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style(colour, 3)));
    Ok(())
}

fn legend<'a, 'b: 'a>(c: &mut Chart<'a, 'b>, pos: SeriesLabelPosition) -> Res<()> {
    c.configure_series_labels()
        .position(pos)
        .label_font(font(15))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK.mix(0.35))
        .draw()
}

/// Runs of a labelled sequence: (start, end, label) with each sample holding until the next.
fn runs<T: Copy + PartialEq>(samples: &[(f64, f64, T)]) -> Vec<(f64, f64, T)> {
    let mut out: Vec<(f64, f64, T)> = Vec::new();
    for &(t0, t1, v) in samples {
        match out.last_mut() {
            Some(last) if last.2 == v && (t0 - last.1).abs() < 1e-9 => last.1 = t1,
            _ => out.push((t0, t1, v)),
        }
    }
    out
}

fn sim_tag(meta: &TrialMeta) -> &'static str {
    if meta.simulated { "SIMULATED — " } else { "" }
}

/// The dominant band and the windowed indicators.
fn plot_indicators(
    path: &Path,
    meta: &TrialMeta,
    rec: &Recorded,
    x: &std::ops::Range<f64>,
) -> PlotResult {
    let root = BitMapBackend::new(path, PX).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (band, main) = root.split_vertically(120);
    // The dominant band: each frame covers (t − Δt, t].
    let frames: Vec<(f64, f64, Option<Indicator>)> = rec
        .indicators
        .iter()
        .zip(&rec.frames)
        .map(|(i, f)| (f.t_s - f.dt_s, f.t_s, i.dominant))
        .collect();
    {
        let mut c = ChartBuilder::on(&band)
            .caption(
                format!(
                    "{}Dominant indicator (coloured band) and windowed indicators",
                    sim_tag(meta)
                ),
                font(22),
            )
            .margin_top(8)
            .margin_left(14)
            .margin_right(24)
            .x_label_area_size(0)
            .y_label_area_size(80)
            .build_cartesian_2d(x.clone(), 0.0..1.0)
            .map_err(err)?;
        c.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_labels(0)
            .y_desc("dominant")
            .axis_desc_style(font(16))
            .draw()
            .map_err(err)?;
        c.draw_series(
            runs(&frames).into_iter().map(|(a, b, k)| {
                Rectangle::new([(a, 0.0), (b, 1.0)], indicator_colour(k).filled())
            }),
        )
        .map_err(err)?;
    }
    let mut c = chart(&main, "", x.clone(), 0.0..1.05, "windowed value [-]", 0).map_err(err)?;
    // The band again, faint, behind the lines.
    c.draw_series(
        runs(&frames)
            .into_iter()
            .filter(|r| r.2.is_some())
            .map(|(a, b, k)| {
                Rectangle::new(
                    [(a, 0.0), (b, 1.05)],
                    indicator_colour(k).mix(0.12).filled(),
                )
            }),
    )
    .map_err(err)?;
    let names = ["AED", "TID", "ICD", "ASD_norm (normalised ASD_ctx)", "OHD"];
    for (j, name) in names.iter().enumerate() {
        let k = Indicator::ALL.get(j).copied();
        let pts = rec
            .indicators
            .iter()
            .map(|i| (i.sample.t, i.windowed.get(j).copied().unwrap_or(f64::NAN)))
            .collect();
        draw_series(&mut c, pts, indicator_colour(k), 2, name).map_err(err)?;
    }
    let pts = rec
        .indicators
        .iter()
        .map(|i| (i.sample.t, i.sample.hrc_cwl_windowed))
        .collect();
    draw_series(&mut c, pts, BLACK, 3, "HRC-CWL (windowed)").map_err(err)?;
    c.draw_series(std::iter::once(Rectangle::new(
        [(x.start, 0.0), (x.start, 0.0)],
        indicator_colour(None).filled(),
    )))
    .map_err(err)?
    .label("band: none")
    .legend(|(x, y)| {
        Rectangle::new(
            [(x, y - 7), (x + 24, y + 7)],
            indicator_colour(None).filled(),
        )
    });
    legend(&mut c, SeriesLabelPosition::UpperRight).map_err(err)?;
    root.present().map_err(err)
}

/// Scales and delays over time.
fn plot_adaptation(
    path: &Path,
    meta: &TrialMeta,
    rec: &Recorded,
    x: &std::ops::Range<f64>,
) -> PlotResult {
    let root = BitMapBackend::new(path, (PX.0, 760)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (top, bottom) = root.split_vertically(400);
    let a = &rec.adaptations;
    let end = x.end;
    {
        let mut c = chart(
            &top,
            &format!("{}Adaptation: speed and smoothness scales", sim_tag(meta)),
            x.clone(),
            0.0..1.22,
            "scale [-]",
            8,
        )
        .map_err(err)?;
        // The active rule as a band along the top, in its indicator's colour.
        let rules: Vec<(f64, f64, Option<Indicator>)> = a
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let t1 = a.get(k + 1).map_or(end, |n| n.t_s);
                let ind = policies::indicator_from_key(r.indicator).flatten();
                (r.t_s, t1, ind)
            })
            .collect();
        c.draw_series(runs(&rules).into_iter().map(|(t0, t1, k)| {
            Rectangle::new([(t0, 1.1), (t1, 1.2)], indicator_colour(k).filled())
        }))
        .map_err(err)?
        .label("band: active rule (indicator colour; grey = none)")
        .legend(|(x, y)| {
            Rectangle::new(
                [(x, y - 7), (x + 24, y + 7)],
                indicator_colour(Some(Indicator::Icd)).filled(),
            )
        });
        for (name, colour, w, f) in [
            (
                "speed scale",
                BLUE,
                7,
                (|r| r.speed_scale) as fn(&super::log::AdaptationRecord) -> f64,
            ),
            ("acceleration scale", ORANGE, 4, |r| r.acceleration_scale),
            ("jerk scale", GREEN, 1, |r| r.jerk_scale),
        ] {
            let pts: Vec<(f64, f64)> = a.iter().map(|r| (r.t_s, f(r))).collect();
            draw_series(&mut c, steps(&pts, end), colour, w, name).map_err(err)?;
        }
        legend(&mut c, SeriesLabelPosition::LowerRight).map_err(err)?;
    }
    let top_y = a
        .iter()
        .map(|r| r.start_delay_s.max(r.min_approach_duration_s))
        .fold(1.0_f64, f64::max)
        * 1.15;
    let mut c = chart(
        &bottom,
        "Adaptation: handover timing",
        x.clone(),
        0.0..top_y,
        "duration [s]",
        8,
    )
    .map_err(err)?;
    for (name, colour, f) in [
        (
            "start delay",
            VERMILION,
            (|r| r.start_delay_s) as fn(&super::log::AdaptationRecord) -> f64,
        ),
        ("minimum approach duration", PURPLE, |r| {
            r.min_approach_duration_s
        }),
    ] {
        let pts: Vec<(f64, f64)> = a.iter().map(|r| (r.t_s, f(r))).collect();
        draw_series(&mut c, steps(&pts, end), colour, 3, name).map_err(err)?;
    }
    legend(&mut c, SeriesLabelPosition::UpperRight).map_err(err)?;
    root.present().map_err(err)
}

/// TCP speed and minimum human distance.
fn plot_robot(
    path: &Path,
    meta: &TrialMeta,
    rec: &Recorded,
    x: &std::ops::Range<f64>,
) -> PlotResult {
    let root = BitMapBackend::new(path, (PX.0, 760)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (top, bottom) = root.split_vertically(380);
    let v_max = rec
        .tcp_speed
        .iter()
        .map(|p| p.1)
        .filter(|v| v.is_finite())
        .fold(0.1_f64, f64::max)
        * 1.15;
    {
        let mut c = chart(
            &top,
            &format!("{}Robot TCP speed", sim_tag(meta)),
            x.clone(),
            0.0..v_max,
            "speed [m/s]",
            8,
        )
        .map_err(err)?;
        draw_series(&mut c, rec.tcp_speed.clone(), BLUE, 2, "TCP speed |v|").map_err(err)?;
        legend(&mut c, SeriesLabelPosition::UpperRight).map_err(err)?;
    }
    let d_max = rec
        .distance
        .iter()
        .filter_map(|p| p.1)
        .filter(|v| v.is_finite())
        .fold(0.5_f64, f64::max)
        * 1.15;
    let mut c = chart(
        &bottom,
        "Minimum human–robot distance",
        x.clone(),
        0.0..d_max,
        "distance [m]",
        8,
    )
    .map_err(err)?;
    // Untracked spans break the line.
    let mut segment: Vec<(f64, f64)> = Vec::new();
    let mut segments = Vec::new();
    for &(t, d) in &rec.distance {
        match d {
            Some(d) if d.is_finite() => segment.push((t, d)),
            _ => segments.push(std::mem::take(&mut segment)),
        }
    }
    segments.push(segment);
    let mut labelled = false;
    for s in segments.into_iter().filter(|s| !s.is_empty()) {
        let series = c
            .draw_series(LineSeries::new(s, style(VERMILION, 2)))
            .map_err(err)?;
        if !labelled {
            series
                .label("min distance (no line: no human point tracked)")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style(VERMILION, 3)));
            labelled = true;
        }
    }
    if labelled {
        legend(&mut c, SeriesLabelPosition::UpperRight).map_err(err)?;
    }
    root.present().map_err(err)
}

/// Motion quality: TCP speed with stop windows and stop-and-go events, executed jerk against
/// the limit, time scale.
fn plot_motion(
    path: &Path,
    meta: &TrialMeta,
    rec: &Recorded,
    summary: &Summary,
    x: &std::ops::Range<f64>,
) -> PlotResult {
    let m = &summary.motion;
    let root = BitMapBackend::new(path, (PX.0, 1000)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (top, rest) = root.split_vertically(400);
    let (middle, bottom) = rest.split_vertically(370);
    let v_max = rec
        .tcp_speed
        .iter()
        .map(|p| p.1)
        .filter(|v| v.is_finite())
        .fold(0.1_f64, f64::max)
        * 1.15;
    {
        let mut c = chart(
            &top,
            &format!(
                "{}TCP speed, stop windows ({} separation, {} other) and {} stop-and-go events outside stops",
                sim_tag(meta),
                m.stop_windows.separation,
                m.stop_windows.other,
                m.stop_and_go.outside_stops
            ),
            x.clone(),
            0.0..v_max,
            "speed [m/s]",
            8,
        )
        .map_err(err)?;
        for (separation, colour, label) in [
            (true, VERMILION, "stop window: SAF-REQ-007 (separation)"),
            (false, GREY, "stop window: other requirement"),
        ] {
            let spans: Vec<(f64, f64)> = m
                .stop_windows
                .windows
                .iter()
                .filter(|w| w.separation == separation)
                .map(|w| (w.start_s, w.start_s + w.duration_s.max(0.004)))
                .collect();
            let any = !spans.is_empty();
            let series = c
                .draw_series(spans.into_iter().map(|(a, b)| {
                    Rectangle::new([(a, 0.0), (b, v_max)], colour.mix(0.22).filled())
                }))
                .map_err(err)?;
            if any {
                series.label(label).legend(move |(x, y)| {
                    Rectangle::new([(x, y - 7), (x + 24, y + 7)], colour.mix(0.35).filled())
                });
            }
        }
        draw_series(&mut c, rec.tcp_speed.clone(), BLUE, 2, "TCP speed |v|").map_err(err)?;
        let events = &m.stop_and_go.events_outside_stops;
        if !events.is_empty() {
            c.draw_series(
                events.iter().map(|e| {
                    TriangleMarker::new((e.start_s, 0.5 * e.peak_m_s), 8, ORANGE.filled())
                }),
            )
            .map_err(err)?
            .label("stop-and-go event outside stops (at half the recent peak)")
            .legend(|(x, y)| TriangleMarker::new((x + 12, y), 8, ORANGE.filled()));
        }
        legend(&mut c, SeriesLabelPosition::UpperRight).map_err(err)?;
    }
    {
        // Jerk on a log scale from 0.1 rad/s³ (smaller values are drawn at 0.1).
        let floor = 0.1;
        let j_max = rec
            .cycles
            .iter()
            .flat_map(|c| [c.jerk_abs_max_rad_s3, 1.1 * c.jerk_limit_rad_s3])
            .filter(|v| v.is_finite())
            .fold(10.0_f64, f64::max)
            * 2.0;
        let mut c = ChartBuilder::on(&middle)
            .caption(
                format!(
                    "Executed jerk (max over joints per 10 ms): {} of {} samples over 1.1 × limit outside stops",
                    m.jerk_limit.outside_stops.exceeding, m.jerk_limit.outside_stops.judged
                ),
                font(22),
            )
            .margin_top(8)
            .margin_left(14)
            .margin_right(24)
            .margin_bottom(6)
            .x_label_area_size(46)
            .y_label_area_size(80)
            .build_cartesian_2d(x.clone(), (floor..j_max).log_scale())
            .map_err(err)?;
        c.configure_mesh()
            .x_desc("trial time t [s]")
            .y_desc("|jerk| [rad/s³]")
            .axis_desc_style(font(18))
            .label_style(font(15))
            .x_labels(12)
            .y_labels(6)
            .light_line_style(TRANSPARENT)
            .bold_line_style(BLACK.mix(0.08))
            .draw()
            .map_err(err)?;
        let jerk: Vec<(f64, f64)> = rec
            .cycles
            .iter()
            .filter(|c| c.jerk_abs_max_rad_s3.is_finite())
            .map(|c| (c.t_s, c.jerk_abs_max_rad_s3.max(floor)))
            .collect();
        c.draw_series(LineSeries::new(jerk, style(BLUE, 1)))
            .map_err(err)?
            .label("executed |jerk|")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style(BLUE, 3)));
        let limit: Vec<(f64, f64)> = rec
            .cycles
            .iter()
            .filter(|c| c.jerk_limit_rad_s3.is_finite() && c.jerk_limit_rad_s3 > 0.0)
            .map(|c| (c.t_s, (1.1 * c.jerk_limit_rad_s3).max(floor)))
            .collect();
        c.draw_series(LineSeries::new(limit, style(VERMILION, 2)))
            .map_err(err)?
            .label("1.1 × planner jerk limit")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style(VERMILION, 3)));
        c.configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font(font(15))
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK.mix(0.35))
            .draw()
            .map_err(err)?;
    }
    let mut c = chart(
        &bottom,
        "Planner time scale",
        x.clone(),
        0.0..1.1,
        "time scale [-]",
        8,
    )
    .map_err(err)?;
    let scale: Vec<(f64, f64)> = rec.cycles.iter().map(|c| (c.t_s, c.time_scale)).collect();
    draw_series(&mut c, scale, GREEN, 2, "time scale s").map_err(err)?;
    legend(&mut c, SeriesLabelPosition::LowerRight).map_err(err)?;
    root.present().map_err(err)
}

/// Colour of a task phase bar.
fn phase_colour(p: &str) -> RGBColor {
    match p {
        "Fetch" => SKY,
        "WaitForAttention" => YELLOW,
        "Approach" => BLUE,
        "Present" => ORANGE,
        "Release" => GREEN,
        "Retreat" => RGBColor(150, 150, 200),
        _ => RGBColor(200, 200, 200),
    }
}

/// Open/closed intervals of an on/off event stream.
fn on_intervals(
    events: &[(f64, TrialEvent)],
    end: f64,
    on: impl Fn(&TrialEvent) -> Option<bool>,
) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut since = None;
    for (t, e) in events {
        match (on(e), since) {
            (Some(true), None) => since = Some(*t),
            (Some(false), Some(s)) => {
                out.push((s, *t));
                since = None;
            }
            _ => {}
        }
    }
    if let Some(s) = since {
        out.push((s, end));
    }
    out
}

/// The handover timeline.
fn plot_handovers(
    path: &Path,
    meta: &TrialMeta,
    rec: &Recorded,
    x: &std::ops::Range<f64>,
) -> PlotResult {
    let root = BitMapBackend::new(path, (PX.0, 470)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (top, strip) = root.split_vertically(410);
    let end = x.end;
    let mut c = ChartBuilder::on(&top)
        .caption(format!("{}Handover timeline", sim_tag(meta)), font(22))
        .margin_top(8)
        .margin_left(14)
        .margin_right(24)
        .margin_bottom(6)
        .x_label_area_size(46)
        .y_label_area_size(150)
        .build_cartesian_2d(x.clone(), 0.0..4.0)
        .map_err(err)?;
    let rows = [
        "hesitation (sim.)",
        "operator idle",
        "handovers",
        "robot task phase",
    ];
    c.configure_mesh()
        .x_desc("trial time t [s]")
        .axis_desc_style(font(18))
        .label_style(font(15))
        .x_labels(12)
        .y_labels(0)
        .light_line_style(TRANSPARENT)
        .bold_line_style(BLACK.mix(0.06))
        .draw()
        .map_err(err)?;
    // Row names, left of the plot, at each row's centre.
    for (k, name) in rows.iter().enumerate() {
        let (px, py) = c.backend_coord(&(x.start, k as f64 + 0.5));
        top.draw(&Text::new(
            *name,
            (px - 8, py),
            font(16).pos(plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Right,
                plotters::style::text_anchor::VPos::Center,
            )),
        ))
        .map_err(err)?;
    }
    // Phases (row 3).
    let mut phases: Vec<(f64, &str)> = Vec::new();
    for (t, e) in &rec.events {
        if let TrialEvent::TaskPhase { phase } = e {
            phases.push((*t, phase));
        }
    }
    let bars: Vec<(f64, f64, &str)> = phases
        .iter()
        .enumerate()
        .map(|(k, &(t, p))| (t, phases.get(k + 1).map_or(end, |n| n.0), p))
        .collect();
    c.draw_series(
        bars.iter()
            .map(|&(a, b, p)| Rectangle::new([(a, 3.15), (b, 3.85)], phase_colour(p).filled())),
    )
    .map_err(err)?;
    let mut seen: Vec<&str> = Vec::new();
    for &(_, _, p) in &bars {
        if !seen.contains(&p) {
            seen.push(p);
        }
    }
    // Operator idle (row 1) and hesitation (row 0).
    let idle = on_intervals(&rec.events, end, |e| match e {
        TrialEvent::OperatorIdle { idle } => Some(*idle),
        _ => None,
    });
    c.draw_series(
        idle.iter()
            .map(|&(a, b)| Rectangle::new([(a, 1.2), (b, 1.8)], GREY.filled())),
    )
    .map_err(err)?;
    let hes = on_intervals(&rec.events, end, |e| match e {
        TrialEvent::Hesitation { active } => Some(*active),
        _ => None,
    });
    c.draw_series(
        hes.iter()
            .map(|&(a, b)| Rectangle::new([(a, 0.2), (b, 0.8)], PURPLE.filled())),
    )
    .map_err(err)?;
    // Handovers (row 2): waiting spans and markers.
    let mut presented: Vec<(u32, f64)> = Vec::new();
    for (t, e) in &rec.events {
        match *e {
            TrialEvent::OperatorNeedsPart { handover } => {
                c.draw_series(std::iter::once(TriangleMarker::new(
                    (*t, 2.2),
                    9,
                    VERMILION.filled(),
                )))
                .map_err(err)?;
                let _ = handover;
            }
            TrialEvent::Presented { handover } => {
                presented.push((handover, *t));
                c.draw_series(std::iter::once(TriangleMarker::new(
                    (*t, 2.5),
                    10,
                    BLUE.filled(),
                )))
                .map_err(err)?;
                c.draw_series(std::iter::once(Text::new(
                    format!("#{handover}"),
                    (*t, 2.92),
                    font(14),
                )))
                .map_err(err)?;
            }
            TrialEvent::Grasped { handover } | TrialEvent::PartReturned { handover } => {
                let grasped = matches!(e, TrialEvent::Grasped { .. });
                if let Some(k) = presented.iter().rposition(|p| p.0 == handover) {
                    let (_, t0) = presented.remove(k);
                    c.draw_series(std::iter::once(Rectangle::new(
                        [(t0, 2.42), (*t, 2.58)],
                        BLUE.mix(0.35).filled(),
                    )))
                    .map_err(err)?;
                }
                if grasped {
                    c.draw_series(std::iter::once(Circle::new((*t, 2.5), 8, GREEN.filled())))
                        .map_err(err)?;
                } else {
                    c.draw_series(std::iter::once(Cross::new(
                        (*t, 2.5),
                        8,
                        style(VERMILION, 3),
                    )))
                    .map_err(err)?;
                }
            }
            _ => {}
        }
    }
    // The legend, in a strip below the plot: phase colours, bars, markers.
    let mut xpx = 170;
    let y = 28;
    let item_font = font(15);
    let mut item = |shape: &dyn Fn((i32, i32)) -> Res<()>, label: &str| -> Res<()> {
        shape((xpx + 10, y))?;
        strip.draw(&Text::new(
            label.to_string(),
            (xpx + 26, y - 8),
            item_font.clone(),
        ))?;
        let w = item_font
            .font
            .box_size(label)
            .map_or(8 * label.len() as i32, |(w, _)| w as i32);
        xpx += 26 + w + 22;
        Ok(())
    };
    for p in seen {
        let colour = phase_colour(p);
        item(
            &|(cx, cy)| {
                strip.draw(&Rectangle::new(
                    [(cx - 10, cy - 8), (cx + 10, cy + 8)],
                    colour.filled(),
                ))
            },
            p,
        )
        .map_err(err)?;
    }
    item(
        &|(cx, cy)| strip.draw(&TriangleMarker::new((cx, cy), 9, BLUE.filled())),
        "presented",
    )
    .map_err(err)?;
    item(
        &|(cx, cy)| strip.draw(&Circle::new((cx, cy), 8, GREEN.filled())),
        "grasped",
    )
    .map_err(err)?;
    item(
        &|(cx, cy)| strip.draw(&Cross::new((cx, cy), 8, style(VERMILION, 3))),
        "returned",
    )
    .map_err(err)?;
    item(
        &|(cx, cy)| strip.draw(&TriangleMarker::new((cx, cy), 9, VERMILION.filled())),
        "operator needs part",
    )
    .map_err(err)?;
    item(
        &|(cx, cy)| {
            strip.draw(&Rectangle::new(
                [(cx - 10, cy - 8), (cx + 10, cy + 8)],
                GREY.filled(),
            ))
        },
        "idle",
    )
    .map_err(err)?;
    item(
        &|(cx, cy)| {
            strip.draw(&Rectangle::new(
                [(cx - 10, cy - 8), (cx + 10, cy + 8)],
                PURPLE.filled(),
            ))
        },
        "hesitation",
    )
    .map_err(err)?;
    root.present().map_err(err)
}

/// Standard base64 (RFC 4648, with padding).
pub(crate) fn base64(bytes: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk.first().copied().unwrap_or(0),
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(T[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn opt(x: Option<f64>, unit: &str) -> String {
    x.map_or_else(|| "–".into(), |v| format!("{v:.3}{unit}"))
}

/// Renders the plots and writes `report.html` into `dir`.
pub(crate) fn write(
    dir: &Path,
    meta: &TrialMeta,
    options: &LogOptions,
    rec: &Recorded,
    summary: &Summary,
) -> crate::Result<ReportFiles> {
    register_font()?;
    let t_end = summary
        .completion_time_s
        .max(rec.frames.last().map_or(0.0, |f| f.t_s));
    let x = 0.0..if t_end > 0.0 { t_end } else { 1.0 };
    let mut plots = Vec::new();
    let mut figures: Vec<(String, PathBuf)> = Vec::new();

    let p = dir.join(INDICATORS_PNG);
    plot_indicators(&p, meta, rec, &x).map_err(plot_error(&p))?;
    figures.push(("Indicators and the dominant indicator".into(), p.clone()));
    plots.push(p);
    if !rec.indicators.is_empty() {
        let samples: Vec<assess_report::Sample> = rec.indicators.iter().map(|i| i.sample).collect();
        let fig = plot::Figure {
            samples: &samples,
            medium_from: options.cwl_medium_from,
            high_from: options.cwl_high_from,
            horizon_s: options.window_horizon_s,
        };
        let written = plot::render(dir, &fig)?;
        if let Some(combined) = written.last() {
            figures.push((
                "Indicator dynamics (cumulative, as in the paper)".into(),
                combined.clone(),
            ));
        }
        plots.extend(written);
    }
    for (title, name, f) in [
        (
            "Adaptations",
            ADAPTATION_PNG,
            plot_adaptation
                as fn(&Path, &TrialMeta, &Recorded, &std::ops::Range<f64>) -> PlotResult,
        ),
        ("Robot speed and human distance", ROBOT_PNG, plot_robot),
        ("Handover timeline", HANDOVERS_PNG, plot_handovers),
    ] {
        let p = dir.join(name);
        f(&p, meta, rec, &x).map_err(plot_error(&p))?;
        figures.push((title.into(), p.clone()));
        plots.push(p);
    }
    let p = dir.join(MOTION_PNG);
    plot_motion(&p, meta, rec, summary, &x).map_err(plot_error(&p))?;
    figures.push(("Motion quality".into(), p.clone()));
    plots.push(p);

    let html = page(meta, summary, &figures)?;
    let path = dir.join(HTML_FILE);
    std::fs::write(&path, html).map_err(Error::io("write", &path))?;
    Ok(ReportFiles { html: path, plots })
}

fn page(meta: &TrialMeta, s: &Summary, figures: &[(String, PathBuf)]) -> crate::Result<String> {
    let mut h = String::new();
    let title = format!(
        "{}Trial {} · {} · {} · seed {}",
        if meta.simulated { "SIMULATED " } else { "" },
        meta.participant,
        meta.condition,
        meta.policy,
        meta.seed
    );
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\n<style>\
body{{font-family:sans-serif;max-width:1450px;margin:1em auto;padding:0 1em;color:#222}}\
.sim{{background:#d55e00;color:#fff;font-size:1.6em;font-weight:bold;padding:.5em 1em;border-radius:6px;letter-spacing:.05em}}\
table{{border-collapse:collapse;margin:.5em 0}}td,th{{border:1px solid #ccc;padding:.25em .6em;text-align:left}}\
th{{background:#f3f3f3}}img{{max-width:100%;border:1px solid #eee}}\
</style></head><body>\n",
        esc(&title)
    );
    if meta.simulated {
        h.push_str("<div class=\"sim\">SIMULATED TRIAL — simulated operator; no person took part. These data are not human measurements.</div>\n");
    }
    if let Some(src) = &meta.cue_source {
        let robot = match meta.robot.as_str() {
            "sim" => "simulated (in-process)",
            "emulator" => "emulated (controller emulator)",
            _ => "real UR5e",
        };
        if let Some(camera) = src.strip_prefix("camera:") {
            let _ = writeln!(
                h,
                "<div class=\"sim\">LIVE CAMERA — operator cues perceived live from {}. Robot: {}.</div>",
                esc(camera),
                esc(robot)
            );
        } else {
            let _ = writeln!(
                h,
                "<div class=\"sim\">RECORDED CUES — operator cues replayed from {}; the recorded operator does not react to the robot. Robot: {}.</div>",
                esc(src),
                esc(robot)
            );
        }
    }
    let _ = writeln!(h, "<h1>{}</h1>", esc(&title));
    let _ = writeln!(h, "<table>");
    for (k, v) in [
        ("participant", meta.participant.clone()),
        ("condition", meta.condition.clone()),
        ("policy", meta.policy.clone()),
        ("seed", meta.seed.to_string()),
        ("simulated", meta.simulated.to_string()),
        (
            "cue source",
            meta.cue_source
                .clone()
                .unwrap_or_else(|| "simulated operator".into()),
        ),
        ("robot", meta.robot.clone()),
        ("started (UTC)", meta.started_utc.clone()),
        ("completion time", format!("{:.3} s", s.completion_time_s)),
        (
            "finish reason",
            s.finish_reason
                .clone()
                .unwrap_or_else(|| "– (not finished cleanly)".into()),
        ),
        ("robot idle", format!("{:.3} s", s.robot_idle_s)),
        ("operator idle", format!("{:.3} s", s.operator_idle_s)),
        (
            "hesitation share (assessed H=1 / C=1)",
            opt(s.hesitation_share.assessed, ""),
        ),
        (
            "hesitation share (simulated ground truth)",
            opt(s.hesitation_share.ground_truth, ""),
        ),
        (
            "HRC-CWL mean cumulative / windowed",
            format!(
                "{} / {}",
                opt(s.hrc_cwl_mean.cumulative, ""),
                opt(s.hrc_cwl_mean.windowed, "")
            ),
        ),
        (
            "HRC-CWL max cumulative / windowed",
            format!(
                "{} / {}",
                opt(s.hrc_cwl_max.cumulative, ""),
                opt(s.hrc_cwl_max.windowed, "")
            ),
        ),
        ("adaptation changes", s.adaptation_changes.total.to_string()),
        ("safety events", s.safety_events.total.to_string()),
    ] {
        let _ = writeln!(h, "<tr><th>{}</th><td>{}</td></tr>", esc(k), esc(&v));
    }
    let _ = writeln!(h, "</table>");
    let _ = writeln!(h, "<h2>Time dominant</h2><table><tr>");
    for k in s.dominant_time_s.keys() {
        let _ = write!(h, "<th>{}</th>", esc(k));
    }
    h.push_str("</tr><tr>");
    for v in s.dominant_time_s.values() {
        let _ = write!(h, "<td>{v:.3} s</td>");
    }
    h.push_str("</tr></table>\n");
    let _ = writeln!(
        h,
        "<h2>Handovers</h2><table><tr><th>#</th><th>robot wait [s]</th><th>operator wait [s]</th><th>returned</th></tr>"
    );
    for ho in &s.handovers {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            ho.index,
            opt(ho.robot_wait_s, ""),
            opt(ho.operator_wait_s, ""),
            if ho.returned { "yes" } else { "no" }
        );
    }
    h.push_str("</table>\n");
    motion_section(&mut h, s);
    for (title, path) in figures {
        let bytes = std::fs::read(path).map_err(Error::io("read", path))?;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let _ = writeln!(
            h,
            "<h2>{}{}</h2>\n<img alt=\"{}\" src=\"data:image/png;base64,{}\">\n<p><a href=\"{}\">{}</a></p>",
            if meta.simulated { "SIMULATED · " } else { "" },
            esc(title),
            esc(title),
            base64(&bytes),
            esc(&name),
            esc(&name)
        );
    }
    h.push_str("<p>Files: <a href=\"trial.mcap\">trial.mcap</a> (open in Foxglove), <a href=\"indicators.csv\">indicators.csv</a>, <a href=\"robot.csv\">robot.csv</a>, <a href=\"summary.json\">summary.json</a>.</p>\n</body></html>\n");
    Ok(h)
}

fn count_opt(x: Option<f64>, unit: &str) -> String {
    x.map_or_else(|| "–".into(), |v| format!("{v:.3} {unit}"))
}

/// The "Motion quality" section: `summary.json`'s `motion` as tables.
fn motion_section(h: &mut String, s: &Summary) {
    let m = &s.motion;
    let _ = writeln!(
        h,
        "<h2>Motion quality</h2>\n<p>From every 500 Hz state, verdict and cycle record (not the \
         decimated or debounced streams); definitions in README.md, \"Motion quality metrics\". \
         A stop window runs from the first Stopped/Halted verdict to {:.1} s after the last one \
         of its run; \"outside stops\" leaves those windows out. SAF-REQ-007 windows are the \
         real separation stops.</p>",
        m.stop_windows.tail_s
    );
    let _ = writeln!(
        h,
        "<table><tr><th>metric</th><th>overall</th><th>outside stops</th></tr>"
    );
    let j = &m.jerk;
    let jl = &m.jerk_limit;
    let rev = &m.velocity_reversals;
    let exceed = |e: &super::log::motion::ExceedSummary| {
        format!(
            "{} of {} ({})",
            e.exceeding,
            e.judged,
            e.share
                .map_or_else(|| "–".into(), |x| format!("{:.2} %", 100.0 * x))
        )
    };
    let rows: Vec<(String, String, String)> = vec![
        (
            "executed jerk RMS (all joints)".into(),
            count_opt(j.overall.rms_rad_s3, "rad/s³"),
            count_opt(j.outside_stops.rms_rad_s3, "rad/s³"),
        ),
        (
            "executed jerk max".into(),
            count_opt(j.overall.max_rad_s3, "rad/s³"),
            count_opt(j.outside_stops.max_rad_s3, "rad/s³"),
        ),
        (
            "jerk RMS per joint [rad/s³]".into(),
            fmt_joints(j.overall.rms_per_joint_rad_s3),
            fmt_joints(j.outside_stops.rms_per_joint_rad_s3),
        ),
        (
            "jerk max per joint [rad/s³]".into(),
            fmt_joints(j.overall.max_per_joint_rad_s3),
            fmt_joints(j.outside_stops.max_per_joint_rad_s3),
        ),
        (
            format!(
                "samples with |jerk| > {:.1} × planner limit ({} – {} rad/s³)",
                jl.factor,
                jl.min_rad_s3
                    .map_or_else(|| "–".into(), |x| format!("{x:.3}")),
                jl.max_rad_s3
                    .map_or_else(|| "–".into(), |x| format!("{x:.3}"))
            ),
            exceed(&jl.overall),
            exceed(&jl.outside_stops),
        ),
        (
            format!(
                "velocity reversals (|q̇| > {} rad/s both sides within {} s), per joint",
                rev.min_speed_rad_s, rev.window_s
            ),
            format!("{} {:?}", rev.overall.total, rev.overall.per_joint),
            format!(
                "{} {:?}",
                rev.outside_stops.total, rev.outside_stops.per_joint
            ),
        ),
        (
            format!(
                "stop-and-go events (below ½ of the {} s peak, back within {} s)",
                m.stop_and_go.peak_window_s, m.stop_and_go.recovery_s
            ),
            m.stop_and_go.overall.to_string(),
            m.stop_and_go.outside_stops.to_string(),
        ),
    ];
    for (k, a, b) in rows {
        let _ = writeln!(
            h,
            "<tr><th>{}</th><td>{}</td><td>{}</td></tr>",
            esc(&k),
            esc(&a),
            esc(&b)
        );
    }
    h.push_str("</table>\n");

    let c = &m.cycles;
    let pct = |p: &Option<super::log::motion::Percentiles>| {
        p.as_ref().map_or_else(
            || "– (mock clock)".into(),
            |p| format!("{:.1} / {:.1} / {:.1} µs", p.p50, p.p99, p.max),
        )
    };
    let _ = writeln!(h, "<table>");
    for (k, v) in [
        (
            "control cycles (commands judged)",
            m.control_cycles.to_string(),
        ),
        (
            "states (repeated, skipped)",
            format!("{} ({})", m.state_samples, m.repeated_states),
        ),
        (
            "missed controller cycles (cycles after a gap, most in one gap)",
            format!(
                "{} ({}, {})",
                c.missed_total, c.cycles_with_missed, c.missed_max
            ),
        ),
        ("cycle latency p50 / p99 / max", pct(&c.latency_us)),
        ("wake jitter p50 / p99 / max", pct(&c.wake_jitter_us)),
        (
            "planner time scale min / mean",
            format!(
                "{} / {}",
                opt(c.time_scale_min, ""),
                opt(c.time_scale_mean, "")
            ),
        ),
        (
            "stop windows (separation / other), time inside",
            format!(
                "{} ({} / {}), {:.3} s",
                m.stop_windows.count,
                m.stop_windows.separation,
                m.stop_windows.other,
                m.stop_windows.time_s
            ),
        ),
    ] {
        let _ = writeln!(h, "<tr><th>{}</th><td>{}</td></tr>", esc(k), esc(&v));
    }
    if let Some(r) = &m.robot_servo {
        let late: u64 = r.late_by_cycles.iter().skip(1).sum();
        let v = format!(
            "{} commands, {} of them late (≥ 1 cycle); {} cycles extrapolated, {} evaluated back \
             (a command meant for a later tick), {} held in {} holds (a moving target older than \
             the robot's extrapolation bound: the arm brakes)",
            r.commands, late, r.extrapolated_cycles, r.early_cycles, r.held_cycles, r.holds
        );
        let _ = writeln!(
            h,
            "<tr><th>{}</th><td>{}</td></tr>",
            esc("robot side (emulator): servo commands"),
            esc(&v)
        );
    }
    if let Some(c) = &m.emulator_clock {
        let v = format!(
            "{} cycles run of {} due; {} slewed (run at 1.25 × the rate after the emulator's \
             thread ran late), {} run late in {} bursts (a backlog beyond 20 ms), {} dropped; \
             largest backlog {} cycles; {} servo holds began in a burst; {} cycles not run \
             while it waited {} times for a late servo command (virtual time stood still), {} \
             of those waits reached the bound",
            c.cycles_run,
            c.cycles_elapsed,
            c.cycles_slewed,
            c.cycles_late,
            c.bursts,
            c.cycles_dropped,
            c.max_behind_cycles,
            c.holds_in_bursts,
            c.cycles_waited,
            c.waits,
            c.waits_timed_out
        );
        let _ = writeln!(
            h,
            "<tr><th>{}</th><td>{}</td></tr>",
            esc("emulator clock (its host, not the client)"),
            esc(&v)
        );
    }
    if let Some(sc) = &m.scheduling {
        let v = format!(
            "control thread {}; RTDE I/O threads {}; emulator clock {}",
            sc.control,
            sc.rtde_io.as_deref().unwrap_or("none"),
            sc.emulator_clock.as_deref().unwrap_or("none")
        );
        let _ = writeln!(
            h,
            "<tr><th>{}</th><td>{}</td></tr>",
            esc("thread scheduling ([realtime])"),
            esc(&v)
        );
    }
    h.push_str("</table>\n");

    let i = &m.interventions;
    let _ = writeln!(
        h,
        "<h3>Supervisor interventions</h3>\n<p>Raw: one count per command judged ({} commands, {} \
         passed). Debounced: the safety events (a pair held for 50 ms).</p>\n<table><tr><th>requirement</th>\
         <th>reduced</th><th>stopped</th><th>halted</th><th>debounced events</th></tr>",
        i.commands, i.passed
    );
    let total = String::from("total");
    for (id, n) in i
        .by_requirement
        .iter()
        .chain(std::iter::once((&total, &i.total)))
    {
        let _ = writeln!(
            h,
            "<tr><th>{}</th><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(id),
            n.reduced,
            n.stopped,
            n.halted,
            n.debounced_events
        );
    }
    h.push_str("</table>\n");

    let w = &m.stop_windows;
    let _ = writeln!(
        h,
        "<h3>Stop windows</h3>\n<p>{} windows, {} with a SAF-REQ-007 stop (a real separation stop: \
         a tracked human point closer than the protective separation distance).{}</p>",
        w.count,
        w.separation,
        if w.windows.len() > WINDOW_ROWS {
            format!(" The first {WINDOW_ROWS} are shown; all are in summary.json.")
        } else {
            String::new()
        }
    );
    if !w.windows.is_empty() {
        h.push_str(
            "<table><tr><th>start [s]</th><th>duration [s]</th><th>stop cycles</th>\
             <th>requirements</th><th>violation (body part, link)</th><th>min human distance [m]</th></tr>\n",
        );
        for win in w.windows.iter().take(WINDOW_ROWS) {
            let _ = writeln!(
                h,
                "<tr><td>{:.3}</td><td>{:.3}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                win.start_s,
                win.duration_s,
                win.stop_cycles,
                esc(&win.requirements.join(", ")),
                esc(&win.violation),
                opt(win.min_human_distance_m, "")
            );
        }
        h.push_str("</table>\n");
    }
}

fn fmt_joints(x: Option<[f64; 6]>) -> String {
    x.map_or_else(
        || "–".into(),
        |a| {
            a.iter()
                .map(|v| format!("{v:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(i.as_bytes()), o);
        }
    }

    #[test]
    fn runs_merge_contiguous_equal_labels() {
        let r = runs(&[(0.0, 1.0, 'a'), (1.0, 2.0, 'a'), (2.0, 3.0, 'b')]);
        assert_eq!(r, vec![(0.0, 2.0, 'a'), (2.0, 3.0, 'b')]);
    }
}
