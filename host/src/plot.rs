//! PNG plots of trajectories and errors.
//!
//! A small in-house renderer on an [`image::RgbImage`]: clipped thick lines, filled rectangles,
//! text from the `font8x8` bitmap glyphs (scaled ×1 for tick labels, ×2 for titles and axis
//! labels), axes with "nice" (1-2-5) ticks, a legend and a title.
//!
//! * [`trajectory_top_view`]: ground truth and (aligned) estimate seen from above, equal aspect.
//! * [`error_over_distance`]: a per-frame error (e.g. the ATE) against distance travelled.
//! * [`per_length_errors`]: KITTI devkit t_rel (%) and r_rel (deg/100 m) bars per segment length.
//! * [`eval_errors`]: the ATE over distance and the per-length bars of an [`EvalReport`].
//! * [`write_eval_plots`]: `trajectory.png` and `errors.png` of an evaluation into a folder.
//!
//! Degenerate input (no points, one point, all points equal, non-finite values) gives a valid
//! picture (an empty frame with a note, or a default ±1 range), never a panic.

use std::path::{Path, PathBuf};

use image::{Rgb, RgbImage};
use semloc_core::geom::Se3;

use crate::eval::{EvalReport, LengthStats};

/// An error writing a plot.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The PNG could not be encoded or written.
    #[error("{}: {source}", path.display())]
    Image {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: image::ImageError,
    },
    /// The output directory could not be created, or a plot file could not be written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The directory or file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
}

type Color = Rgb<u8>;
const WHITE: Color = Rgb([255, 255, 255]);
const BLACK: Color = Rgb([0, 0, 0]);
const GRID: Color = Rgb([225, 225, 225]);
const GREY: Color = Rgb([110, 110, 110]);
/// Colour of ground truth (dark grey-blue).
const GT_COLOR: Color = Rgb([40, 40, 40]);
/// Colour of the estimate (red).
const EST_COLOR: Color = Rgb([220, 40, 30]);
/// Second series colour (blue).
const BLUE: Color = Rgb([30, 90, 200]);

/// A raster canvas with the primitives the plots need. Everything is clipped to the image.
struct Canvas {
    img: RgbImage,
}

impl Canvas {
    fn new(w: u32, h: u32) -> Self {
        Canvas { img: RgbImage::from_pixel(w, h, WHITE) }
    }

    fn put(&mut self, x: i64, y: i64, c: Color) {
        if x >= 0
            && y >= 0
            && (x as u64) < self.img.width() as u64
            && (y as u64) < self.img.height() as u64
        {
            self.img.put_pixel(x as u32, y as u32, c);
        }
    }

    fn fill_rect(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, c: Color) {
        let (w, h) = (self.img.width() as f64, self.img.height() as f64);
        let xa = x0.min(x1).round().clamp(0.0, w) as i64;
        let xb = x0.max(x1).round().clamp(0.0, w) as i64;
        let ya = y0.min(y1).round().clamp(0.0, h) as i64;
        let yb = y0.max(y1).round().clamp(0.0, h) as i64;
        for y in ya..yb {
            for x in xa..xb {
                self.put(x, y, c);
            }
        }
    }

    fn rect_outline(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, c: Color) {
        self.line(x0, y0, x1, y0, c, 1);
        self.line(x1, y0, x1, y1, c, 1);
        self.line(x1, y1, x0, y1, c, 1);
        self.line(x0, y1, x0, y0, c, 1);
    }

    /// A line `width` pixels thick (Bresenham with a square pen), clipped to the image first so
    /// far-away endpoints cost nothing.
    fn line(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, c: Color, width: u32) {
        let (w, h) = (self.img.width() as f64, self.img.height() as f64);
        let Some((x0, y0, x1, y1)) = clip(x0, y0, x1, y1, -2.0, -2.0, w + 2.0, h + 2.0) else {
            return;
        };
        let (mut x, mut y) = (x0.round() as i64, y0.round() as i64);
        let (xe, ye) = (x1.round() as i64, y1.round() as i64);
        let (dx, dy) = ((xe - x).abs(), -(ye - y).abs());
        let (sx, sy) = (if x < xe { 1 } else { -1 }, if y < ye { 1 } else { -1 });
        let mut err = dx + dy;
        let lo = -((width as i64 - 1) / 2);
        let hi = width as i64 / 2;
        loop {
            for oy in lo..=hi {
                for ox in lo..=hi {
                    self.put(x + ox, y + oy, c);
                }
            }
            if x == xe && y == ye {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// Text with its top-left corner at `(x, y)`, each glyph pixel drawn as `scale`×`scale`.
    fn text(&mut self, x: f64, y: f64, s: &str, scale: u32, c: Color) {
        let (x, y, k) = (x.round() as i64, y.round() as i64, scale as i64);
        for (i, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            for (row, bits) in g.iter().enumerate() {
                for col in 0..8 {
                    if bits >> col & 1 == 1 {
                        let px = x + (i as i64 * 8 + col) * k;
                        let py = y + row as i64 * k;
                        for oy in 0..k {
                            for ox in 0..k {
                                self.put(px + ox, py + oy, c);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Text rotated 90° counter-clockwise (reads bottom to top), its bottom-left at `(x, y)`.
    fn text_up(&mut self, x: f64, y: f64, s: &str, scale: u32, c: Color) {
        let (x, y, k) = (x.round() as i64, y.round() as i64, scale as i64);
        for (i, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            for (row, bits) in g.iter().enumerate() {
                for col in 0..8 {
                    if bits >> col & 1 == 1 {
                        // Glyph (col, row) → image (x + row, y - (i*8 + col)).
                        let px = x + row as i64 * k;
                        let py = y - (i as i64 * 8 + col + 1) * k;
                        for oy in 0..k {
                            for ox in 0..k {
                                self.put(px + ox, py + oy, c);
                            }
                        }
                    }
                }
            }
        }
    }

    fn text_centered(&mut self, cx: f64, y: f64, s: &str, scale: u32, c: Color) {
        self.text(cx - text_width(s, scale) / 2.0, y, s, scale, c);
    }

    /// A title centred at the top, at double size when it fits the width, else single size.
    fn title(&mut self, s: &str) {
        let w = self.img.width() as f64;
        let scale = if text_width(s, 2) <= w - 20.0 { 2 } else { 1 };
        self.text_centered(w / 2.0, if scale == 2 { 15.0 } else { 20.0 }, s, scale, BLACK);
    }

    /// Encodes the PNG in memory and writes it through a temporary file and a rename, so a
    /// failed write (disk full) never leaves a truncated image.
    fn save(&self, path: &Path) -> Result<(), PlotError> {
        let mut png = std::io::Cursor::new(Vec::new());
        self.img
            .write_to(&mut png, image::ImageFormat::Png)
            .map_err(|source| PlotError::Image { path: path.to_path_buf(), source })?;
        crate::run::stream::write_atomic_io(path, png.get_ref())
            .map_err(|source| PlotError::Io { path: path.to_path_buf(), source })
    }
}

/// Draws `s` in the 8x8 bitmap font with its top-left at `(x, y)` (clipped to the image).
pub(crate) fn draw_text(img: &mut image::RgbImage, x: u32, y: u32, s: &str, rgb: [u8; 3]) {
    for (i, ch) in s.chars().enumerate() {
        for (row, bits) in glyph(ch).iter().enumerate() {
            for col in 0..8u32 {
                if bits >> col & 1 == 1 {
                    let (px, py) = (x + i as u32 * 8 + col, y + row as u32);
                    if px < img.width() && py < img.height() {
                        img.put_pixel(px, py, image::Rgb(rgb));
                    }
                }
            }
        }
    }
}

fn text_width(s: &str, scale: u32) -> f64 {
    (s.chars().count() * 8 * scale as usize) as f64
}

fn glyph(ch: char) -> [u8; 8] {
    let code = ch as u32;
    if code < 128 {
        font8x8::legacy::BASIC_LEGACY[code as usize]
    } else if (0xA0..0x100).contains(&code) {
        font8x8::legacy::LATIN_LEGACY[(code - 0xA0) as usize]
    } else {
        font8x8::legacy::BASIC_LEGACY[b'?' as usize]
    }
}

/// Liang–Barsky clipping of a segment to a rectangle; `None` when it lies outside (or is NaN).
#[allow(clippy::too_many_arguments)]
fn clip(
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
    xmin: f64,
    ymin: f64,
    xmax: f64,
    ymax: f64,
) -> Option<(f64, f64, f64, f64)> {
    if ![x0, y0, x1, y1].iter().all(|v| v.is_finite()) {
        return None;
    }
    let (dx, dy) = (x1 - x0, y1 - y0);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, x0 - xmin), (dx, xmax - x0), (-dy, y0 - ymin), (dy, ymax - y0)] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then_some((x0 + t0 * dx, y0 + t0 * dy, x0 + t1 * dx, y0 + t1 * dy))
}

/// A "nice" tick step (1, 2 or 5 × 10^k) giving about `target` intervals over `range`.
fn nice_step(range: f64, target: f64) -> f64 {
    let raw = (range / target).max(1e-12);
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let nice = if f < 1.5 {
        1.0
    } else if f < 3.0 {
        2.0
    } else if f < 7.0 {
        5.0
    } else {
        10.0
    };
    nice * mag
}

fn tick_label(v: f64, step: f64) -> String {
    if v.abs() >= 1e6 {
        return format!("{v:.2e}");
    }
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    let s = format!("{:.*}", decimals.min(6), v);
    if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') {
        s[1..].to_string()
    } else {
        s
    }
}

/// A data range `[lo, hi]` covering `vals` (finite ones), padded by `pad` of its size; a
/// degenerate or empty range becomes a ±1 window.
fn range_of(vals: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    if span <= 1e-9 * lo.abs().max(1.0) {
        return (lo - 1.0, hi + 1.0);
    }
    (lo - pad * span, hi + pad * span)
}

/// A plot area: a pixel rectangle and the data window mapped onto it (y up).
struct Axes {
    px: (f64, f64, f64, f64),
    x: (f64, f64),
    y: (f64, f64),
}

impl Axes {
    fn map(&self, x: f64, y: f64) -> (f64, f64) {
        let (l, t, r, b) = self.px;
        (
            l + (x - self.x.0) / (self.x.1 - self.x.0) * (r - l),
            b - (y - self.y.0) / (self.y.1 - self.y.0) * (b - t),
        )
    }

    /// Grid, frame, ticks with labels and axis labels.
    fn draw(&self, cv: &mut Canvas, xlabel: &str, ylabel: &str, xticks: bool) {
        let (l, t, r, b) = self.px;
        let xs = nice_step(self.x.1 - self.x.0, ((r - l) / 90.0).max(2.0));
        let ys = nice_step(self.y.1 - self.y.0, ((b - t) / 70.0).max(2.0));
        let mut widest: f64 = 0.0;
        if xticks {
            for v in ticks(self.x, xs) {
                let (px, _) = self.map(v, self.y.0);
                cv.line(px, t, px, b, GRID, 1);
                cv.line(px, b, px, b + 5.0, BLACK, 1);
                cv.text_centered(px, b + 9.0, &tick_label(v, xs), 1, BLACK);
            }
        }
        for v in ticks(self.y, ys) {
            let (_, py) = self.map(self.x.0, v);
            cv.line(l, py, r, py, GRID, 1);
            cv.line(l - 5.0, py, l, py, BLACK, 1);
            let s = tick_label(v, ys);
            widest = widest.max(text_width(&s, 1));
            cv.text(l - 8.0 - text_width(&s, 1), py - 4.0, &s, 1, BLACK);
        }
        cv.rect_outline(l, t, r, b, BLACK);
        cv.text_centered((l + r) / 2.0, b + 26.0, xlabel, 2, BLACK);
        let ylen = text_width(ylabel, 2);
        cv.text_up(l - 14.0 - widest - 16.0, (t + b) / 2.0 + ylen / 2.0, ylabel, 2, BLACK);
    }
}

fn ticks(range: (f64, f64), step: f64) -> Vec<f64> {
    let first = (range.0 / step).ceil() as i64;
    let last = (range.1 / step).floor() as i64;
    if last < first || last - first > 1000 {
        return Vec::new();
    }
    (first..=last).map(|k| k as f64 * step).collect()
}

fn draw_polyline(cv: &mut Canvas, ax: &Axes, pts: &[(f64, f64)], c: Color, width: u32) {
    let mapped: Vec<(f64, f64)> = pts
        .iter()
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .map(|&(x, y)| ax.map(x, y))
        .collect();
    match mapped.as_slice() {
        [] => {}
        [(x, y)] => cv.fill_rect(x - 3.0, y - 3.0, x + 4.0, y + 4.0, c),
        _ => {
            for w in mapped.windows(2) {
                cv.line(w[0].0, w[0].1, w[1].0, w[1].1, c, width);
            }
        }
    }
}

/// A legend box in the top-left corner of `ax`.
fn legend(cv: &mut Canvas, ax: &Axes, entries: &[(&str, Color)]) {
    let (l, t, _, _) = ax.px;
    let w = entries.iter().map(|(s, _)| text_width(s, 2)).fold(0.0, f64::max) + 60.0;
    let h = entries.len() as f64 * 24.0 + 10.0;
    let (x0, y0) = (l + 10.0, t + 10.0);
    cv.fill_rect(x0, y0, x0 + w, y0 + h, WHITE);
    cv.rect_outline(x0, y0, x0 + w, y0 + h, GREY);
    for (i, (s, c)) in entries.iter().enumerate() {
        let y = y0 + 10.0 + i as f64 * 24.0;
        cv.line(x0 + 8.0, y + 8.0, x0 + 40.0, y + 8.0, *c, 3);
        cv.text(x0 + 50.0, y, s, 2, BLACK);
    }
}

fn note(cv: &mut Canvas, ax: &Axes, s: &str) {
    let (l, t, r, b) = ax.px;
    cv.text_centered((l + r) / 2.0, (t + b) / 2.0 - 8.0, s, 2, GREY);
}

/// Writes a top view of two trajectories: points are `(horizontal, vertical)` in metres — for
/// KITTI camera coordinates use `(x, z)` (see [`top_view_xz`]). Equal aspect ratio; the ground
/// truth in dark grey, the estimate in red, with a legend and `title`.
pub fn trajectory_top_view(
    path: impl AsRef<Path>,
    gt: &[(f64, f64)],
    est: &[(f64, f64)],
    title: &str,
) -> Result<(), PlotError> {
    let (w, h) = (900u32, 900u32);
    let mut cv = Canvas::new(w, h);
    let px = (100.0, 50.0, w as f64 - 30.0, h as f64 - 70.0);
    let all = || gt.iter().chain(est);
    let (mut x0, mut x1) = range_of(all().map(|p| p.0), 0.05);
    let (mut y0, mut y1) = range_of(all().map(|p| p.1), 0.05);
    // Equal aspect: widen the tighter direction so metres per pixel agree.
    let (pw, ph) = (px.2 - px.0, px.3 - px.1);
    let mpp = ((x1 - x0) / pw).max((y1 - y0) / ph);
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    (x0, x1) = (cx - mpp * pw / 2.0, cx + mpp * pw / 2.0);
    (y0, y1) = (cy - mpp * ph / 2.0, cy + mpp * ph / 2.0);
    let ax = Axes { px, x: (x0, x1), y: (y0, y1) };
    ax.draw(&mut cv, "x [m]", "z [m]", true);
    draw_polyline(&mut cv, &ax, gt, GT_COLOR, 2);
    draw_polyline(&mut cv, &ax, est, EST_COLOR, 2);
    if let Some(&(sx, sy)) = gt.first().filter(|p| p.0.is_finite() && p.1.is_finite()) {
        let (x, y) = ax.map(sx, sy);
        cv.rect_outline(x - 6.0, y - 6.0, x + 6.0, y + 6.0, BLACK);
    }
    if gt.is_empty() && est.is_empty() {
        note(&mut cv, &ax, "no poses");
    }
    legend(&mut cv, &ax, &[("ground truth", GT_COLOR), ("estimate", EST_COLOR), ("start", WHITE)]);
    // The legend's "start" entry gets the start marker instead of a line.
    let (l, t, _, _) = ax.px;
    let (mx, my) = (l + 18.0 + 16.0, t + 20.0 + 2.0 * 24.0 + 8.0);
    cv.rect_outline(mx - 6.0, my - 6.0, mx + 6.0, my + 6.0, BLACK);
    cv.title(title);
    cv.save(path.as_ref())
}

/// `(x, z)` of every pose: the top view of a trajectory in KITTI camera coordinates
/// (x right, y down, z forward).
pub fn top_view_xz(poses: &[Se3]) -> Vec<(f64, f64)> {
    poses.iter().map(|p| (p.trans.x, p.trans.z)).collect()
}

/// Draws an error-over-distance line panel into the pixel rectangle `px`.
fn draw_error_over_distance(
    cv: &mut Canvas,
    px: (f64, f64, f64, f64),
    distance: &[f64],
    error: &[f64],
    ylabel: &str,
) {
    let pts: Vec<(f64, f64)> = distance.iter().copied().zip(error.iter().copied()).collect();
    let (x0, x1) = range_of(pts.iter().map(|p| p.0), 0.0);
    let (_, y1) = range_of(pts.iter().map(|p| p.1).chain([0.0]), 0.08);
    let y0 = pts.iter().map(|p| p.1).filter(|v| v.is_finite()).fold(0.0, f64::min);
    let ax = Axes { px, x: (x0, x1), y: (y0, y1) };
    ax.draw(cv, "distance [m]", ylabel, true);
    draw_polyline(cv, &ax, &pts, EST_COLOR, 2);
    if pts.is_empty() {
        note(cv, &ax, "no data");
    }
}

/// Draws the two per-length bar panels (t_rel, r_rel) side by side between `left` and `right`,
/// `top` to `bottom` (pixels).
fn draw_per_length(
    cv: &mut Canvas,
    rows: &[LengthStats],
    left: f64,
    right: f64,
    top: f64,
    bottom: f64,
) {
    type Panel = (&'static str, Color, fn(&LengthStats) -> f64);
    let panels: [Panel; 2] = [
        ("t_rel [%]", EST_COLOR, |r| r.t_rel_pct),
        ("r_rel [deg/100 m]", BLUE, |r| r.r_rel_deg_per_100m),
    ];
    // Each panel keeps 100 px on its left for tick labels and the axis label.
    let pw = (right - left - 100.0) / 2.0 - 100.0;
    for (k, (label, color, value)) in panels.into_iter().enumerate() {
        let l = left + k as f64 * (pw + 200.0);
        let px = (l, top, l + pw, bottom);
        let (_, y1) = range_of(rows.iter().map(value).chain([0.0]), 0.1);
        let n = rows.len().max(1) as f64;
        let ax = Axes { px, x: (0.0, n), y: (0.0, y1) };
        ax.draw(cv, "segment length [m]", label, false);
        for (i, r) in rows.iter().enumerate() {
            let v = value(r);
            let (bx0, by) = ax.map(i as f64 + 0.15, if v.is_finite() { v.max(0.0) } else { 0.0 });
            let (bx1, b0) = ax.map(i as f64 + 0.85, 0.0);
            cv.fill_rect(bx0, by, bx1, b0, color);
            let cx = (bx0 + bx1) / 2.0;
            cv.line(cx, px.3, cx, px.3 + 5.0, BLACK, 1);
            cv.text_centered(cx, px.3 + 9.0, &format!("{:.0}", r.length_m), 1, BLACK);
            cv.text_centered(cx, by - 12.0, &format!("{v:.2}"), 1, BLACK);
        }
        if rows.is_empty() {
            note(cv, &ax, "no segments");
        }
    }
}

/// Writes a line plot of a per-frame error against distance travelled, e.g. the ATE of every
/// frame against ground-truth distance. `distance` and `error` pair up (extra entries of the
/// longer one are ignored); `ylabel` names the error and its unit.
pub fn error_over_distance(
    path: impl AsRef<Path>,
    distance: &[f64],
    error: &[f64],
    ylabel: &str,
    title: &str,
) -> Result<(), PlotError> {
    let (w, h) = (1000u32, 500u32);
    let mut cv = Canvas::new(w, h);
    draw_error_over_distance(
        &mut cv,
        (100.0, 50.0, w as f64 - 30.0, h as f64 - 70.0),
        distance,
        error,
        ylabel,
    );
    cv.title(title);
    cv.save(path.as_ref())
}

/// Writes the KITTI devkit errors per segment length as two bar panels: t_rel (%) and
/// r_rel (deg/100 m), one bar per length (as in [`EvalReport::per_length`]).
pub fn per_length_errors(
    path: impl AsRef<Path>,
    rows: &[LengthStats],
    title: &str,
) -> Result<(), PlotError> {
    let (w, h) = (1100u32, 500u32);
    let mut cv = Canvas::new(w, h);
    draw_per_length(&mut cv, rows, 100.0, w as f64 - 30.0, 50.0, h as f64 - 70.0);
    cv.title(title);
    cv.save(path.as_ref())
}

/// Writes an error figure for an evaluation: the ATE of every frame against ground-truth
/// distance travelled (top) and the devkit t_rel / r_rel per segment length (bottom).
pub fn eval_errors(
    path: impl AsRef<Path>,
    report: &EvalReport,
    title: &str,
) -> Result<(), PlotError> {
    let (w, h) = (1100u32, 900u32);
    let mut cv = Canvas::new(w, h);
    let ylabel = format!("ATE ({}) [m]", report.align);
    draw_error_over_distance(
        &mut cv,
        (100.0, 50.0, w as f64 - 30.0, 420.0),
        &report.gt_distances_m,
        &report.ate_errors_m,
        &ylabel,
    );
    draw_per_length(&mut cv, &report.per_length, 100.0, w as f64 - 30.0, 510.0, h as f64 - 70.0);
    cv.title(title);
    cv.save(path.as_ref())
}

/// Writes the plots of an evaluation into `dir` (created if needed) and returns their paths:
/// `trajectory.png` — top view (x, z) of `gt` and the aligned estimate, equal aspect;
/// `errors.png` — ATE over distance travelled and devkit errors per segment length
/// (see [`eval_errors`]).
pub fn write_eval_plots(
    dir: impl AsRef<Path>,
    gt: &[Se3],
    report: &EvalReport,
) -> Result<Vec<PathBuf>, PlotError> {
    let dir = dir.as_ref();
    std::fs::create_dir_all(dir)
        .map_err(|source| PlotError::Io { path: dir.to_path_buf(), source })?;
    let top = dir.join("trajectory.png");
    let errors = dir.join("errors.png");
    let summary = match (report.t_rel_pct, report.r_rel_deg_per_100m) {
        (Some(t), Some(r)) => {
            format!(
                "t_rel {t:.2}%, r_rel {r:.2} deg/100m, ATE({}) {:.2} m",
                report.align, report.ate_rmse_m
            )
        }
        _ => format!("ATE({}) {:.2} m", report.align, report.ate_rmse_m),
    };
    trajectory_top_view(&top, &top_view_xz(gt), &top_view_xz(&report.aligned_est), &summary)?;
    let title = match report.t_rel_pct {
        Some(_) => format!("ATE rmse {:.3} m; KITTI devkit errors per length", report.ate_rmse_m),
        None => format!("ATE rmse {:.3} m; no devkit segments (path < 100 m)", report.ate_rmse_m),
    };
    eval_errors(&errors, report, &title)?;
    Ok(vec![top, errors])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nonwhite(path: &Path) -> usize {
        let img = image::open(path).unwrap().to_rgb8();
        img.pixels().filter(|p| **p != WHITE).count()
    }

    #[test]
    fn degenerate_inputs_do_not_panic() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("a.png");
        let cases: [&[(f64, f64)]; 5] = [
            &[],
            &[(1.0, 2.0)],
            &[(3.0, 3.0); 10],
            &[(f64::NAN, 0.0), (1.0, f64::INFINITY), (0.0, 0.0), (1e12, -1e12)],
            &[(0.0, 0.0), (0.0, 100.0)],
        ];
        for pts in cases {
            trajectory_top_view(&f, pts, pts, "t").unwrap();
            assert!(nonwhite(&f) > 0);
            let xs: Vec<f64> = pts.iter().map(|p| p.0).collect();
            let ys: Vec<f64> = pts.iter().map(|p| p.1).collect();
            error_over_distance(&f, &xs, &ys, "e [m]", "t").unwrap();
        }
        per_length_errors(&f, &[], "t").unwrap();
        let row = LengthStats {
            length_m: 100.0,
            n_segments: 1,
            t_rel_pct: f64::NAN,
            r_rel_deg_per_100m: 0.0,
        };
        per_length_errors(&f, &[row], "t").unwrap();
    }

    #[test]
    fn unwritable_path_is_an_error_naming_it() {
        let e = trajectory_top_view("/nonexistent-dir/x.png", &[], &[], "t").unwrap_err();
        assert!(e.to_string().contains("x.png"));
    }

    #[test]
    fn nice_ticks_and_clipping() {
        assert_eq!(nice_step(100.0, 5.0), 20.0);
        assert_eq!(nice_step(1.0, 4.0), 0.2);
        assert_eq!(tick_label(-0.0, 0.5), "0.0");
        assert_eq!(tick_label(250.0, 50.0), "250");
        assert_eq!(tick_label(-2.5e12, 1e12), "-2.50e12");
        assert_eq!(clip(-10.0, 5.0, 20.0, 5.0, 0.0, 0.0, 10.0, 10.0), Some((0.0, 5.0, 10.0, 5.0)));
        assert_eq!(clip(-10.0, -5.0, -1.0, -5.0, 0.0, 0.0, 10.0, 10.0), None);
    }

    #[test]
    fn report_plots_are_written() {
        use crate::eval::{evaluate, Align};
        use nalgebra::{Rotation3, Vector3};
        let gt: Vec<Se3> = (0..400)
            .map(|i| {
                let a = i as f64 * 0.01;
                Se3::new(
                    Rotation3::from_euler_angles(0.0, a, 0.0).into_inner(),
                    Vector3::new(100.0 * (1.0 - a.cos()), 0.0, 100.0 * a.sin()),
                )
            })
            .collect();
        let est: Vec<Se3> = gt.iter().map(|p| Se3::new(p.rot, p.trans * 1.02)).collect();
        let r = evaluate(&gt, &est, Align::Se3).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let files = write_eval_plots(dir.path().join("plots"), &gt, &r).unwrap();
        assert_eq!(files.len(), 2);
        for f in files {
            assert!(nonwhite(&f) > 1000, "{}", f.display());
        }
    }
}
