//! The cue CSV format: one recorded frame of [`CueFrame`] per row.
//!
//! ```text
//! # Lines that start with `#` are comments; blank lines are skipped.
//! t,head_x,head_y,head_z,head_fx,head_fy,head_fz,head_conf,body_x,body_y,body_z,body_fx,body_fy,body_fz,body_conf,lhand_x,lhand_y,lhand_z,lhand_conf,rhand_x,rhand_y,rhand_z,rhand_conf,collaborating,incomplete
//! 0.0,0.0,0.0,1.2,0.5,0.0,-0.4,0.9,,,,,,,,,,,,0.45,0.1,0.85,0.8,0,0
//! ```
//!
//! - The first non-comment row is the header. Columns are matched by name, in any order; every
//!   name must be one of [`COLUMNS`], and none may repeat.
//! - `t` (frame time [s]) is required. It must be finite and strictly increasing from row to row.
//! - The cue groups (head: `head_x..head_conf`, body: `body_x..body_conf`, left hand:
//!   `lhand_x..lhand_conf`, right hand: `rhand_x..rhand_conf`) may be left out of the header as a
//!   whole; the cue is then missing on every frame. A group present in the header must be complete.
//! - In a row, a cue whose cells are all empty is missing. Otherwise every cell of the group must be
//!   a finite number: positions in the workspace frame [m], facing vectors (any length; the model
//!   normalises them) [-], confidences in [0, 1] [-].
//! - `collaborating` (C(t)) and `incomplete` (G(t)) are `0`, `1`, `false` or `true`; an empty cell
//!   or an absent column means 0.
//! - Cells may be padded with spaces and enclosed in double quotes; they never contain commas.
//!   Lines may end in `\n` or `\r\n`; a leading UTF-8 byte-order mark is skipped.
//!
//! [`write()`] writes every column, with the shortest decimal form of each number that reads back
//! to the same `f64` (Rust's `{:?}`), so a written file reads back bit for bit.
//!
//! Errors name the file, the 1-based line and column (field number) and the offending cell, e.g.
//! `cues.csv:17:2: expected a number in column `head_x`, got "abc"`.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::Path;

use crate::Vec3;
use crate::cue::{BodyCue, CueFrame, HandCue, HeadCue, RobotContext};
use crate::error::{AssessError, Result};

/// Every column of the format, in the order [`write()`] writes them.
pub const COLUMNS: [&str; 25] = [
    "t",
    "head_x",
    "head_y",
    "head_z",
    "head_fx",
    "head_fy",
    "head_fz",
    "head_conf",
    "body_x",
    "body_y",
    "body_z",
    "body_fx",
    "body_fy",
    "body_fz",
    "body_conf",
    "lhand_x",
    "lhand_y",
    "lhand_z",
    "lhand_conf",
    "rhand_x",
    "rhand_y",
    "rhand_z",
    "rhand_conf",
    "collaborating",
    "incomplete",
];

const T: usize = 0;
const HEAD: usize = 1;
const BODY: usize = 8;
const LHAND: usize = 15;
const RHAND: usize = 19;
const COLLABORATING: usize = 23;
const INCOMPLETE: usize = 24;
/// Column groups that are present or absent as a whole: (name, first column, width).
const GROUPS: [(&str, usize, usize); 4] = [
    ("head", HEAD, 7),
    ("body", BODY, 7),
    ("lhand", LHAND, 4),
    ("rhand", RHAND, 4),
];

/// Reads a cue CSV file (format in the module docs).
///
/// Fails with [`AssessError::Io`] when the file cannot be read and [`AssessError::Csv`] (file,
/// line, column) when it is malformed.
pub fn read(path: &Path) -> Result<Vec<CueFrame>> {
    let file = File::open(path).map_err(|source| AssessError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    read_from(BufReader::new(file), path)
}

/// Reads a cue CSV document from any reader; `origin` names it in errors.
pub fn read_from<R: BufRead>(reader: R, origin: &Path) -> Result<Vec<CueFrame>> {
    let mut lines = Lines {
        reader,
        origin,
        buf: Vec::new(),
        text: String::new(),
        line: 0,
    };
    let fail = |line: u64, column: usize, message: String| AssessError::Csv {
        path: origin.to_path_buf(),
        line,
        column,
        message,
    };

    // --- header ---
    if !lines.next_row()? {
        return Err(fail(
            1,
            1,
            "empty file: expected a header row starting with `t`".into(),
        ));
    }
    let header_line = lines.line;
    // `field[c]`: the field index of column c, if the header has it.
    let mut field: [Option<usize>; COLUMNS.len()] = [None; COLUMNS.len()];
    let mut width = 0;
    for (i, name) in split(&lines.text).enumerate() {
        width += 1;
        let Some(c) = COLUMNS.iter().position(|&n| n == name) else {
            return Err(fail(
                header_line,
                i + 1,
                format!("unknown column `{name}` (expected {})", COLUMNS.join(", ")),
            ));
        };
        if field[c].is_some() {
            return Err(fail(
                header_line,
                i + 1,
                format!("column `{name}` appears twice"),
            ));
        }
        field[c] = Some(i);
    }
    if field[T].is_none() {
        return Err(fail(header_line, 1, "the header has no `t` column".into()));
    }
    for (group, first, width) in GROUPS {
        let cols = first..first + width;
        let given = cols.clone().filter(|&c| field[c].is_some()).count();
        if given != 0 && given != width {
            let missing: Vec<&str> = cols
                .filter(|&c| field[c].is_none())
                .map(|c| COLUMNS[c])
                .collect();
            return Err(fail(
                header_line,
                1,
                format!(
                    "the `{group}` cue is incomplete: the header lacks {} (give all of its columns or none)",
                    missing.join(", ")
                ),
            ));
        }
    }

    // --- rows ---
    let mut frames = Vec::new();
    let mut prev_t: Option<(f64, u64)> = None;
    while lines.next_row()? {
        let line = lines.line;
        let cells: Vec<&str> = split(&lines.text).collect();
        if cells.len() != width {
            return Err(fail(
                line,
                cells.len().min(width) + 1,
                format!(
                    "expected {width} fields as in the header, got {}",
                    cells.len()
                ),
            ));
        }
        let row = Row {
            cells: &cells,
            field: &field,
            line,
            origin,
        };
        let t = match row.cell(T) {
            Some("") | None => return Err(row.error(T, "missing time in column `t`".into())),
            Some(_) => row.number(T)?,
        };
        if let Some((prev, prev_line)) = prev_t.filter(|&(prev, _)| t <= prev) {
            return Err(row.error(
                T,
                format!("time must increase from row to row: {t} [s] follows {prev} [s] (line {prev_line})"),
            ));
        }
        prev_t = Some((t, line));
        let head = row.group(HEAD, 7)?.map(|v| HeadCue {
            position: Vec3::new(v[0], v[1], v[2]),
            facing: Vec3::new(v[3], v[4], v[5]),
            confidence: v[6],
        });
        let body = row.group(BODY, 7)?.map(|v| BodyCue {
            position: Vec3::new(v[0], v[1], v[2]),
            facing: Vec3::new(v[3], v[4], v[5]),
            confidence: v[6],
        });
        let hand = |first| -> Result<Option<HandCue>> {
            Ok(row.group(first, 4)?.map(|v| HandCue {
                position: Vec3::new(v[0], v[1], v[2]),
                confidence: v[3],
            }))
        };
        frames.push(CueFrame {
            t,
            head,
            body,
            hands: [hand(LHAND)?, hand(RHAND)?],
            robot: RobotContext {
                collaborating: row.flag(COLLABORATING)?,
                incomplete: row.flag(INCOMPLETE)?,
            },
        });
    }
    Ok(frames)
}

/// Writes frames as a cue CSV file (every column; format in the module docs).
///
/// Fails with [`AssessError::InvalidValue`] when a frame could not be read back: a non-finite
/// value, a confidence outside [0, 1], or a time that does not increase. Nothing is written then.
pub fn write(path: &Path, frames: &[CueFrame]) -> Result<()> {
    check_frames(frames)?;
    let io_err = |source| AssessError::Write {
        path: path.to_path_buf(),
        source,
    };
    let file = File::create(path).map_err(io_err)?;
    let mut out = BufWriter::new(file);
    write_unchecked(&mut out, frames).map_err(io_err)?;
    out.flush().map_err(io_err)
}

/// Writes frames as a cue CSV document to any writer (see [`write()`]). I/O errors are reported
/// with `<writer>` as the path.
pub fn write_to<W: Write>(mut writer: W, frames: &[CueFrame]) -> Result<()> {
    check_frames(frames)?;
    write_unchecked(&mut writer, frames).map_err(|source| AssessError::Write {
        path: "<writer>".into(),
        source,
    })
}

fn write_unchecked<W: Write>(writer: &mut W, frames: &[CueFrame]) -> std::io::Result<()> {
    let mut line = String::with_capacity(512);
    line.push_str(&COLUMNS.join(","));
    line.push('\n');
    writer.write_all(line.as_bytes())?;
    for f in frames {
        line.clear();
        push_num(&mut line, f.t);
        match &f.head {
            Some(h) => push_nums(
                &mut line,
                &[h.position.as_slice(), h.facing.as_slice(), &[h.confidence]],
            ),
            None => line.push_str(",,,,,,,"),
        }
        match &f.body {
            Some(b) => push_nums(
                &mut line,
                &[b.position.as_slice(), b.facing.as_slice(), &[b.confidence]],
            ),
            None => line.push_str(",,,,,,,"),
        }
        for hand in &f.hands {
            match hand {
                Some(m) => push_nums(&mut line, &[m.position.as_slice(), &[m.confidence]]),
                None => line.push_str(",,,,"),
            }
        }
        line.push_str(if f.robot.collaborating { ",1" } else { ",0" });
        line.push_str(if f.robot.incomplete { ",1" } else { ",0" });
        line.push('\n');
        writer.write_all(line.as_bytes())?;
    }
    Ok(())
}

fn push_num(line: &mut String, v: f64) {
    use std::fmt::Write as _;
    // `{:?}` is the shortest form that parses back to the same f64 (and keeps the sign of -0.0).
    let _ = write!(line, "{v:?}");
}

fn push_nums(line: &mut String, parts: &[&[f64]]) {
    for v in parts.iter().flat_map(|p| p.iter()) {
        line.push(',');
        push_num(line, *v);
    }
}

/// The reader's rules, applied to frames before writing them.
fn check_frames(frames: &[CueFrame]) -> Result<()> {
    let mut prev: Option<f64> = None;
    for (k, f) in frames.iter().enumerate() {
        let key = |what: &str| format!("frames[{k}].{what}");
        if !f.t.is_finite() {
            return Err(AssessError::invalid(
                key("t"),
                format!("must be finite (got {})", f.t),
            ));
        }
        if let Some(p) = prev.filter(|&p| f.t <= p) {
            return Err(AssessError::invalid(
                key("t"),
                format!("time must increase: {} [s] follows {p} [s]", f.t),
            ));
        }
        prev = Some(f.t);
        let mut cues: Vec<(&str, Vec3, Option<Vec3>, f64)> = Vec::with_capacity(4);
        if let Some(h) = &f.head {
            cues.push(("head", h.position, Some(h.facing), h.confidence));
        }
        if let Some(b) = &f.body {
            cues.push(("body", b.position, Some(b.facing), b.confidence));
        }
        for (name, hand) in ["hands[0]", "hands[1]"].into_iter().zip(&f.hands) {
            if let Some(m) = hand {
                cues.push((name, m.position, None, m.confidence));
            }
        }
        for (name, position, facing, confidence) in cues {
            let finite = position
                .iter()
                .chain(facing.iter().flatten())
                .all(|v| v.is_finite());
            if !finite {
                return Err(AssessError::invalid(
                    key(name),
                    "every value must be finite (write a missing cue as `None`)",
                ));
            }
            if !(0.0..=1.0).contains(&confidence) {
                return Err(AssessError::invalid(
                    key(name),
                    format!("confidence must lie in [0, 1] (got {confidence})"),
                ));
            }
        }
    }
    Ok(())
}

/// The data lines of a document: comment (`#`) and blank lines are skipped, a trailing `\r` is
/// dropped, and `line` counts every physical line (1-based).
struct Lines<'a, R> {
    reader: R,
    origin: &'a Path,
    buf: Vec<u8>,
    /// The current data line, without its line break.
    text: String,
    /// 1-based number of the current line.
    line: u64,
}

impl<R: BufRead> Lines<'_, R> {
    /// Advances to the next data line; false at the end of the document.
    fn next_row(&mut self) -> Result<bool> {
        loop {
            self.buf.clear();
            let n = self
                .reader
                .read_until(b'\n', &mut self.buf)
                .map_err(|source| AssessError::Io {
                    path: self.origin.to_path_buf(),
                    source,
                })?;
            if n == 0 {
                return Ok(false);
            }
            self.line += 1;
            let mut bytes = self.buf.as_slice();
            for end in [b'\n', b'\r'] {
                if let Some(rest) = bytes.strip_suffix(&[end]) {
                    bytes = rest;
                }
            }
            if self.line == 1 {
                // A UTF-8 byte-order mark, as some spreadsheet programs write.
                bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
            }
            let text = std::str::from_utf8(bytes).map_err(|e| {
                let column = bytes[..e.valid_up_to()]
                    .iter()
                    .filter(|&&b| b == b',')
                    .count()
                    + 1;
                AssessError::Csv {
                    path: self.origin.to_path_buf(),
                    line: self.line,
                    column,
                    message: "the cell is not valid UTF-8".into(),
                }
            })?;
            let trimmed = text.trim();
            if trimmed.is_empty() || trimmed.starts_with('#') {
                continue;
            }
            self.text.clear();
            self.text.push_str(text);
            return Ok(true);
        }
    }
}

/// The cells of a line: split at commas, trimmed, with one pair of enclosing double quotes removed.
fn split(line: &str) -> impl Iterator<Item = &str> {
    line.split(',').map(|cell| {
        let cell = cell.trim();
        cell.strip_prefix('"')
            .and_then(|c| c.strip_suffix('"'))
            .map_or(cell, str::trim)
    })
}

/// One data row, with what is needed to locate its cells in errors.
struct Row<'a> {
    cells: &'a [&'a str],
    field: &'a [Option<usize>; COLUMNS.len()],
    line: u64,
    origin: &'a Path,
}

impl Row<'_> {
    /// The cell of column `c`, `None` when the header lacks the column.
    fn cell(&self, c: usize) -> Option<&str> {
        self.field[c].and_then(|i| self.cells.get(i).copied())
    }

    fn error(&self, c: usize, message: String) -> AssessError {
        AssessError::Csv {
            path: self.origin.to_path_buf(),
            line: self.line,
            column: self.field[c].map_or(1, |i| i + 1),
            message,
        }
    }

    fn number(&self, c: usize) -> Result<f64> {
        let cell = self.cell(c).unwrap_or("");
        match cell.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(self.error(
                c,
                format!(
                    "expected a finite number in column `{}`, got {cell:?}",
                    COLUMNS[c]
                ),
            )),
            Err(_) => Err(self.error(
                c,
                format!("expected a number in column `{}`, got {cell:?}", COLUMNS[c]),
            )),
        }
    }

    /// The `width` values of the group starting at column `first` (in `v[..width]`; the rest stay
    /// 0); `None` when the group is absent from the header or all its cells are empty. The last
    /// value, `v[width - 1]`, is a confidence.
    fn group(&self, first: usize, width: usize) -> Result<Option<[f64; 7]>> {
        let cols = first..first + width;
        if cols.clone().all(|c| self.cell(c).is_none_or(str::is_empty)) {
            return Ok(None);
        }
        let mut v = [0.0; 7];
        for (k, c) in cols.enumerate() {
            if self.cell(c).is_none_or(str::is_empty) {
                let group = &COLUMNS[first][..COLUMNS[first].len() - 2];
                return Err(self.error(
                    c,
                    format!(
                        "missing value in column `{}`: the `{group}` cue must be complete or all empty",
                        COLUMNS[c]
                    ),
                ));
            }
            v[k] = self.number(c)?;
        }
        let conf = first + width - 1;
        if !(0.0..=1.0).contains(&v[width - 1]) {
            return Err(self.error(
                conf,
                format!(
                    "expected a confidence in [0, 1] in column `{}`, got {}",
                    COLUMNS[conf],
                    v[width - 1]
                ),
            ));
        }
        Ok(Some(v))
    }

    fn flag(&self, c: usize) -> Result<bool> {
        match self.cell(c).unwrap_or("") {
            "" | "0" | "false" => Ok(false),
            "1" | "true" => Ok(true),
            other => Err(self.error(
                c,
                format!("expected 0 or 1 in column `{}`, got {other:?}", COLUMNS[c]),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn origin() -> &'static Path {
        Path::new("cues.csv")
    }

    fn parse(text: &str) -> Result<Vec<CueFrame>> {
        read_from(text.as_bytes(), origin())
    }

    fn err(text: &str) -> String {
        parse(text).unwrap_err().to_string()
    }

    /// Frames that exercise every column, with values that have no short decimal form.
    fn sample_frames() -> Vec<CueFrame> {
        let mut frames = Vec::new();
        for k in 0..50u32 {
            let x = f64::from(k);
            let mut f = CueFrame::empty(x / 30.0 + 0.1);
            if k % 3 != 0 {
                f.head = Some(HeadCue {
                    position: Vec3::new(0.1 * x, -1.0 / 3.0, 1.2 + 1e-9 * x),
                    facing: Vec3::new(std::f64::consts::PI, -0.0, -0.4),
                    confidence: 0.9 - 0.001 * x,
                });
            }
            if k % 4 != 1 {
                f.body = Some(BodyCue {
                    position: Vec3::new(1e-300, 2.5e17, -x.sqrt()),
                    facing: Vec3::new(0.7, 0.7, 0.0),
                    confidence: 1.0,
                });
            }
            if k % 5 != 2 {
                f.hands[0] = Some(HandCue {
                    position: Vec3::new(0.45, 0.1 * x.sin(), 0.85),
                    confidence: 0.0,
                });
            }
            if k % 2 == 0 {
                f.hands[1] = Some(HandCue {
                    position: Vec3::new(0.3, 0.2, 0.9 + x.cos()),
                    confidence: 0.5,
                });
            }
            f.robot.collaborating = k % 7 < 3;
            f.robot.incomplete = k % 11 < 6;
            frames.push(f);
        }
        frames
    }

    fn header() -> String {
        COLUMNS.join(",")
    }

    #[test]
    fn written_frames_read_back_bit_exactly() {
        let frames = sample_frames();
        let mut buf = Vec::new();
        write_to(&mut buf, &frames).unwrap();
        let back = parse(std::str::from_utf8(&buf).unwrap()).unwrap();
        assert_eq!(back.len(), frames.len());
        for (a, b) in frames.iter().zip(&back) {
            // PartialEq on f64 would accept 0.0 == -0.0; compare the bits.
            let bits = |f: &CueFrame| {
                let mut v = vec![f.t.to_bits()];
                if let Some(h) = f.head {
                    v.extend(
                        h.position
                            .iter()
                            .chain(h.facing.iter())
                            .map(|x| x.to_bits()),
                    );
                    v.push(h.confidence.to_bits());
                }
                if let Some(b) = f.body {
                    v.extend(
                        b.position
                            .iter()
                            .chain(b.facing.iter())
                            .map(|x| x.to_bits()),
                    );
                    v.push(b.confidence.to_bits());
                }
                for m in f.hands.iter().flatten() {
                    v.extend(m.position.iter().map(|x| x.to_bits()));
                    v.push(m.confidence.to_bits());
                }
                v
            };
            assert_eq!(a, b);
            assert_eq!(bits(a), bits(b));
        }
    }

    #[test]
    fn writes_to_a_file_and_reads_it_back() {
        let dir = std::env::temp_dir().join(format!("assess-cue-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("cues.csv");
        let frames = sample_frames();
        write(&path, &frames).unwrap();
        assert_eq!(read(&path).unwrap(), frames);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn empty_cells_are_missing_cues_and_groups_may_be_left_out() {
        let text = "# a recording with the head cue and the right hand only\n\
                    t, head_x,head_y,head_z,head_fx,head_fy,head_fz,head_conf, rhand_x,rhand_y,rhand_z,rhand_conf, collaborating\n\
                    0.0, 0,0,1.2, 1,0,0, 0.9, , , , , 1\n\
                    \n\
                    # dropped frame\n\
                    0.1, ,,,,,,, 0.5,0.1,0.8,0.7,\n";
        let frames = parse(text).unwrap();
        assert_eq!(frames.len(), 2);
        let h = frames[0].head.unwrap();
        assert_eq!(h.position, Vec3::new(0.0, 0.0, 1.2));
        assert_eq!(h.confidence, 0.9);
        assert!(frames[0].body.is_none() && frames[0].hands == [None, None]);
        assert_eq!(
            frames[0].robot,
            RobotContext {
                collaborating: true,
                incomplete: false
            }
        );
        assert!(frames[1].head.is_none());
        assert_eq!(
            frames[1].hands[1].unwrap().position,
            Vec3::new(0.5, 0.1, 0.8)
        );
        assert_eq!(frames[1].robot, RobotContext::default());
    }

    #[test]
    fn a_bad_number_names_file_line_and_column() {
        // Line 1 is a comment, line 2 the header, line 3 a good row; line 4 has "abc" in head_x,
        // the second field.
        let h = header();
        let good = "0.0,0,0,1.2,1,0,0,0.9,,,,,,,,,,,,,,,,0,0";
        let bad = "0.1,abc,0,1.2,1,0,0,0.9,,,,,,,,,,,,,,,,0,0";
        let text = format!("# recorded\n{h}\n{good}\n{bad}\n");
        assert_eq!(
            err(&text),
            "cues.csv:4:2: expected a number in column `head_x`, got \"abc\""
        );
    }

    #[test]
    fn malformed_rows_are_located() {
        let h = header();
        let cases: [(&str, &str); 7] = [
            // A partial cue: head_y empty (field 3).
            (
                "0.0,0,,1.2,1,0,0,0.9,,,,,,,,,,,,,,,,0,0",
                "cues.csv:2:3: missing value in column `head_y`: the `head` cue must be complete or all empty",
            ),
            // Confidence out of range (field 8).
            (
                "0.0,0,0,1.2,1,0,0,1.5,,,,,,,,,,,,,,,,0,0",
                "cues.csv:2:8: expected a confidence in [0, 1] in column `head_conf`, got 1.5",
            ),
            // Non-finite value (field 9, body_x).
            (
                "0.0,,,,,,,,NaN,0,1,1,0,0,1,,,,,,,,,0,0",
                "cues.csv:2:9: expected a finite number in column `body_x`, got \"NaN\"",
            ),
            // A bad flag (field 25).
            (
                "0.0,,,,,,,,,,,,,,,,,,,,,,,0,yes",
                "cues.csv:2:25: expected 0 or 1 in column `incomplete`, got \"yes\"",
            ),
            // Too few fields: 3 given, so field 4 is the first one missing.
            (
                "0.0,1,2",
                "cues.csv:2:4: expected 25 fields as in the header, got 3",
            ),
            // No time.
            (
                ",,,,,,,,,,,,,,,,,,,,,,,0,0",
                "cues.csv:2:1: missing time in column `t`",
            ),
            // The time in scientific notation is fine, but a hand confidence below 0 is not.
            (
                "1e-3,,,,,,,,,,,,,,,0.1,0.2,0.3,-0.5,,,,,0,0",
                "cues.csv:2:19: expected a confidence in [0, 1] in column `lhand_conf`, got -0.5",
            ),
        ];
        for (row, want) in cases {
            assert_eq!(err(&format!("{h}\n{row}\n")), want, "row {row}");
        }
    }

    #[test]
    fn line_numbers_count_comment_and_blank_lines() {
        // CRLF line ends, a comment and a blank line before and between rows, a quoted cell.
        let text = "# one\r\n\r\nt, collaborating\r\n# four\r\n0.0,\"1\"\r\n\r\n0.1,2\r\n";
        assert_eq!(
            err(text),
            "cues.csv:7:2: expected 0 or 1 in column `collaborating`, got \"2\""
        );
        let frames = parse(&text.replace(",2", ",true")).unwrap();
        assert_eq!(frames.len(), 2);
        assert!(frames[0].robot.collaborating && frames[1].robot.collaborating);
        // Invalid UTF-8 in the third field of line 2.
        let bytes = b"t,incomplete,collaborating\n0.0,0,\xFF\n";
        assert_eq!(
            read_from(&bytes[..], origin()).unwrap_err().to_string(),
            "cues.csv:2:3: the cell is not valid UTF-8"
        );
    }

    #[test]
    fn time_must_increase() {
        let text = "t\n0.0\n0.5\n0.5\n";
        assert_eq!(
            err(text),
            "cues.csv:4:1: time must increase from row to row: 0.5 [s] follows 0.5 [s] (line 3)"
        );
    }

    #[test]
    fn bad_headers_are_rejected() {
        assert_eq!(
            err(""),
            "cues.csv:1:1: empty file: expected a header row starting with `t`"
        );
        assert_eq!(
            err("# only a comment\n"),
            "cues.csv:1:1: empty file: expected a header row starting with `t`"
        );
        assert!(
            err("t,head_X\n")
                .starts_with("cues.csv:1:2: unknown column `head_X` (expected t, head_x,")
        );
        assert_eq!(
            err("t,incomplete,incomplete\n"),
            "cues.csv:1:3: column `incomplete` appears twice"
        );
        assert_eq!(
            err("# c\nhead_x\n"),
            "cues.csv:2:1: the header has no `t` column"
        );
        assert_eq!(
            err("t,lhand_x,lhand_y,lhand_z\n"),
            "cues.csv:1:1: the `lhand` cue is incomplete: the header lacks lhand_conf (give all of its columns or none)"
        );
    }

    #[test]
    fn writer_refuses_what_the_reader_would_reject() {
        let mut frames = sample_frames();
        frames[3].t = frames[2].t;
        assert_eq!(
            write_to(Vec::new(), &frames).unwrap_err().to_string(),
            format!(
                "invalid value for `frames[3].t`: time must increase: {} [s] follows {} [s]",
                frames[2].t, frames[2].t
            )
        );
        let mut frames = sample_frames();
        frames[1].head.as_mut().unwrap().facing.x = f64::INFINITY;
        assert!(
            write_to(Vec::new(), &frames)
                .unwrap_err()
                .to_string()
                .starts_with("invalid value for `frames[1].head`")
        );
        let mut frames = sample_frames();
        frames[0].hands[1].as_mut().unwrap().confidence = 1.01;
        assert_eq!(
            write_to(Vec::new(), &frames).unwrap_err().to_string(),
            "invalid value for `frames[0].hands[1]`: confidence must lie in [0, 1] (got 1.01)"
        );
    }

    #[test]
    fn a_missing_file_is_an_io_error_naming_it() {
        let e = read(Path::new("/nonexistent/cues.csv")).unwrap_err();
        assert!(matches!(e, AssessError::Io { .. }));
        assert!(
            e.to_string()
                .starts_with("cannot read /nonexistent/cues.csv: ")
        );
    }
}
