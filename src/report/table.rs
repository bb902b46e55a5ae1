//! `indicators.csv`: one row per assessed frame.
//!
//! Formatting is fixed so that the same input gives the same bytes: times and every real value
//! with 6 decimals (`{:.6}`, with −0 written as 0; [`Precision::Fixed6`], the default) or as
//! the shortest text that reads back to the same `f64` ([`Precision::Full`]), booleans as `0`/`1`, area states by name
//! (`none` for ∅), categories and the dominant indicator by their lower-case/paper names, and an
//! empty cell for a hand speed that is undefined (no hand).

use std::io::Write;

use assess::{Assessment, Indicators, Workspace};

/// The ten per-indicator columns, each written with a `cum_` (cumulative from the first frame)
/// and a `win_` (sliding window) prefix.
pub(crate) const INDICATOR_COLUMNS: [&str; 10] = [
    "aed", "tid", "icd", "col", "abi", "asd_ctx", "asd_norm", "ohd", "hrc_cwl", "category",
];

/// The columns before the indicators.
const LEADING: [&str; 5] = ["t", "F", "F_per", "F_act", "valid"];

/// The columns after the indicators.
const TRAILING: [&str; 6] = [
    "collaborating",
    "hesitating",
    "hand_speed_m_s",
    "v_th_m_s",
    "dominant",
    "dominant_strength",
];

/// Every column of `indicators.csv`, in order.
pub(crate) fn header() -> Vec<String> {
    let mut h: Vec<String> = LEADING.iter().map(|s| s.to_string()).collect();
    for prefix in ["cum", "win"] {
        h.extend(INDICATOR_COLUMNS.iter().map(|c| format!("{prefix}_{c}")));
    }
    h.extend(TRAILING.iter().map(|s| s.to_string()));
    h
}

/// How real values are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub(crate) enum Precision {
    /// 6 decimals (−0 and what rounds to it as `0.000000`): for reading and plotting.
    #[default]
    #[value(name = "6")]
    Fixed6,
    /// The shortest text that parses back to the same `f64` (Rust's `{:?}`, `-0.0` kept): for
    /// checking the model to the last bit.
    Full,
}

impl Precision {
    /// `x` as this precision writes it.
    pub(crate) fn format(self, x: f64) -> String {
        match self {
            Precision::Fixed6 => fixed(x),
            Precision::Full => format!("{x:?}"),
        }
    }
}

/// A real value with 6 decimals; −0 (and values that round to it) are written as `0.000000`.
pub(crate) fn fixed(x: f64) -> String {
    let s = format!("{x:.6}");
    if s == "-0.000000" {
        "0.000000".into()
    } else {
        s
    }
}

fn flag(b: bool) -> &'static str {
    if b { "1" } else { "0" }
}

/// Writes `indicators.csv` row by row.
#[derive(Debug)]
pub(crate) struct IndicatorTable<W: Write> {
    out: csv::Writer<W>,
    row: Vec<String>,
    precision: Precision,
}

impl<W: Write> IndicatorTable<W> {
    /// Starts a table with 6 decimals: writes the header.
    pub(crate) fn new(writer: W) -> csv::Result<Self> {
        Self::with_precision(writer, Precision::Fixed6)
    }

    /// Starts a table writing reals with `precision`: writes the header.
    pub(crate) fn with_precision(writer: W, precision: Precision) -> csv::Result<Self> {
        let mut out = csv::WriterBuilder::new().from_writer(writer);
        let header = header();
        out.write_record(&header)?;
        Ok(Self {
            out,
            row: Vec::with_capacity(header.len()),
            precision,
        })
    }

    /// Writes the row of one assessment.
    pub(crate) fn write(&mut self, ws: &Workspace, a: &Assessment) -> csv::Result<()> {
        let row = &mut self.row;
        let p = self.precision;
        let real = |x: f64| p.format(x);
        row.clear();
        row.push(real(a.t));
        row.push(ws.state_name(a.confirmed).to_string());
        row.push(ws.state_name(a.perceptual.0).to_string());
        row.push(ws.state_name(a.action.0).to_string());
        row.push(flag(a.valid).into());
        for ind in [&a.cumulative, &a.windowed] {
            push_indicators(row, ind, p);
        }
        row.push(flag(a.collaborating).into());
        row.push(flag(a.hesitating).into());
        row.push(a.hand_speed_m_s.map(real).unwrap_or_default());
        row.push(real(a.speed_threshold_m_s));
        row.push(a.dominant.indicator.map_or("none", |i| i.name()).into());
        row.push(real(a.dominant.strength));
        self.out.write_record(&*row)
    }

    /// Flushes and returns the writer.
    pub(crate) fn finish(self) -> std::io::Result<W> {
        self.out.into_inner().map_err(|e| e.into_error())
    }
}

fn push_indicators(row: &mut Vec<String>, i: &Indicators, p: Precision) {
    for v in [
        i.aed, i.tid, i.icd, i.col, i.abi, i.asd_ctx, i.asd_norm, i.ohd, i.hrc_cwl,
    ] {
        row.push(p.format(v));
    }
    row.push(i.category.name().into());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_has_every_indicator_twice() {
        let h = header();
        assert_eq!(h.len(), 5 + 2 * 10 + 6);
        assert_eq!(&h[..6], ["t", "F", "F_per", "F_act", "valid", "cum_aed"]);
        assert_eq!(h[14], "cum_category");
        assert_eq!(h[15], "win_aed");
        assert_eq!(h[24], "win_category");
        assert_eq!(h[30], "dominant_strength");
    }

    #[test]
    fn fixed_formatting_is_stable() {
        assert_eq!(fixed(0.0), "0.000000");
        assert_eq!(fixed(-0.0), "0.000000");
        assert_eq!(fixed(-1e-9), "0.000000");
        assert_eq!(fixed(1.0 / 3.0), "0.333333");
        assert_eq!(fixed(2.5e-7), "0.000000");
        assert_eq!(fixed(12.3456789), "12.345679");
    }

    #[test]
    fn full_precision_reads_back_bit_for_bit() {
        for x in [0.1 + 0.2, 1.0 / 3.0, -0.0, 5e-324, 12.3456789, 1e300, 0.0] {
            let s = Precision::Full.format(x);
            assert_eq!(
                s.parse::<f64>().unwrap().to_bits(),
                x.to_bits(),
                "{x:e} as {s}"
            );
        }
        assert_eq!(
            Precision::Full.format(0.30000000000000004),
            "0.30000000000000004"
        );
        assert_eq!(Precision::Fixed6.format(0.30000000000000004), "0.300000");
    }
}
