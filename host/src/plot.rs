//! Plots of trajectories and errors, each written as SVG and PNG, drawn with `plotters`.
//!
//! Text uses DejaVu Sans embedded in the binary (the `dejavu` crate; the font's licence is the
//! Bitstream Vera licence plus public-domain DejaVu changes, which allow embedding and
//! redistribution): no system font is looked up, so the plots look the same on any machine.
//!
//! * [`write_eval_plots`]: the figures of one evaluation — `trajectory` (top view), `ate`
//!   (ATE over distance travelled), `rpe` (RPE over time), `position` (x, y, z over time),
//!   `orientation` (roll, pitch, yaw over time) and `per_length` (devkit errors per segment
//!   length), each as `NAME.svg` and `NAME.png`.
//! * [`write_overlay_top_view`]: one top view with several estimates (the rows of
//!   `semloc ablate` / `semloc demo`) over the ground truth.
//! * [`draw_label`]: a line of text into an image (the class legend of `semloc segment`).
//!
//! Every title names the alignment the plotted figures went through (see [`align_name`]).
//! Files are written through [`crate::run::stream::write_atomic_io`]: a reader sees the old
//! file, the new one or none. Degenerate input (no points, one point, all points equal,
//! non-finite values) gives a valid picture, never a panic: non-finite points are left out.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;
use semloc_core::geom::Se3;

use crate::eval::{Align, EvalReport};

/// An error writing a plot.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The PNG could not be encoded.
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
    /// Drawing the figure failed (the embedded font could not be loaded, or `plotters`
    /// reported an error).
    #[error("{}: drawing the plot failed: {message}", path.display())]
    Draw {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// The font family every text is drawn in (registered with the embedded DejaVu Sans).
const FONT: &str = "sans-serif";

/// Registers the embedded font once; `false` when it could not be parsed.
fn font_ready() -> bool {
    static READY: OnceLock<bool> = OnceLock::new();
    *READY.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
    })
}

/// Colour of the ground truth.
const GT_COLOR: RGBColor = RGBColor(40, 40, 40);
/// Colours of estimates, in order (the first is the estimate of a single run).
const PALETTE: [RGBColor; 8] = [
    RGBColor(214, 39, 40),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Mark {
    /// A polyline.
    Line,
    /// A polyline with a dot at every point.
    LinePoints,
    /// One ring at each point (e.g. the start of a trajectory).
    Ring,
}

/// One named series of `(x, y)` points.
#[derive(Clone, Debug)]
struct Series {
    name: String,
    points: Vec<(f64, f64)>,
    color: RGBColor,
    mark: Mark,
}

impl Series {
    fn line(name: impl Into<String>, points: Vec<(f64, f64)>, color: RGBColor) -> Self {
        Self { name: name.into(), points, color, mark: Mark::Line }
    }
}

/// One chart of a figure.
#[derive(Clone, Debug)]
struct Panel {
    /// Shown above the chart (may be empty).
    caption: String,
    xlabel: String,
    ylabel: String,
    series: Vec<Series>,
    /// One metre on x is as long as one metre on y (top views).
    equal_aspect: bool,
    /// The y range includes 0 (errors).
    from_zero: bool,
}

impl Panel {
    fn new(xlabel: &str, ylabel: &str, series: Vec<Series>) -> Self {
        Self {
            caption: String::new(),
            xlabel: xlabel.to_owned(),
            ylabel: ylabel.to_owned(),
            series,
            equal_aspect: false,
            from_zero: false,
        }
    }
}

/// A titled figure of panels stacked top to bottom.
#[derive(Clone, Debug)]
struct Figure {
    title: String,
    size: (u32, u32),
    panels: Vec<Panel>,
}

/// Outer margin of a panel (px).
const MARGIN: u32 = 12;
/// Height of the x tick labels and axis label (px).
const X_LABEL_AREA: u32 = 48;
/// Width of the y tick labels and axis label (px).
const Y_LABEL_AREA: u32 = 78;
/// Height of a panel caption (px).
const CAPTION_AREA: u32 = 26;

/// A data range `[lo, hi]` covering the finite `vals`, padded by `pad` of its size; a
/// degenerate or empty range becomes a ±1 window around it.
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

/// Widens the tighter of two ranges so that a plotting area of `pw` × `ph` pixels shows both
/// at the same units per pixel (equal axis scale), keeping their centres.
fn equal_aspect(x: (f64, f64), y: (f64, f64), pw: f64, ph: f64) -> ((f64, f64), (f64, f64)) {
    let (pw, ph) = (pw.max(1.0), ph.max(1.0));
    let upp = ((x.1 - x.0) / pw).max((y.1 - y.0) / ph);
    let (cx, cy) = ((x.0 + x.1) / 2.0, (y.0 + y.1) / 2.0);
    ((cx - upp * pw / 2.0, cx + upp * pw / 2.0), (cy - upp * ph / 2.0, cy + upp * ph / 2.0))
}

fn finite(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    points.iter().copied().filter(|p| p.0.is_finite() && p.1.is_finite()).collect()
}

/// Draws `panel` into `area`.
fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let all: Vec<(f64, f64)> = panel.series.iter().flat_map(|s| finite(&s.points)).collect();
    let (mut xr, mut yr) = (
        range_of(all.iter().map(|p| p.0), if panel.equal_aspect { 0.05 } else { 0.0 }),
        range_of(
            all.iter().map(|p| p.1).chain(panel.from_zero.then_some(0.0)),
            if panel.equal_aspect { 0.05 } else { 0.08 },
        ),
    );
    if panel.from_zero && yr.0 < 0.0 && all.iter().all(|p| p.1 >= 0.0) {
        yr.0 = 0.0;
    }
    let caption_h = if panel.caption.is_empty() { 0 } else { CAPTION_AREA };
    if panel.equal_aspect {
        let (w, h) = area.dim_in_pixel();
        let pw = f64::from(w.saturating_sub(2 * MARGIN + Y_LABEL_AREA));
        let ph = f64::from(h.saturating_sub(2 * MARGIN + X_LABEL_AREA + caption_h));
        (xr, yr) = equal_aspect(xr, yr, pw, ph);
    }
    let mut builder = ChartBuilder::on(area);
    builder.margin(MARGIN).x_label_area_size(X_LABEL_AREA).y_label_area_size(Y_LABEL_AREA);
    if !panel.caption.is_empty() {
        builder.caption(&panel.caption, (FONT, 17));
    }
    let mut chart = builder.build_cartesian_2d(xr.0..xr.1, yr.0..yr.1).map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(panel.xlabel.as_str())
        .y_desc(panel.ylabel.as_str())
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 15))
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(e)?;
    let mut labelled = false;
    for s in &panel.series {
        let pts = finite(&s.points);
        let color = s.color;
        let style = color.stroke_width(2);
        let drawn = match s.mark {
            Mark::Line | Mark::LinePoints if pts.len() == 1 => {
                chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, style.filled())))
            }
            Mark::Line => chart.draw_series(LineSeries::new(pts, style)),
            Mark::LinePoints => chart.draw_series(LineSeries::new(pts, style).point_size(4)),
            Mark::Ring => chart.draw_series(pts.iter().map(|&p| Circle::new(p, 7, style))),
        }
        .map_err(e)?;
        if !s.name.is_empty() {
            labelled = true;
            let mark = s.mark;
            drawn.label(s.name.as_str()).legend(move |(x, y)| -> DynElement<'static, DB, _> {
                if mark == Mark::Ring {
                    Circle::new((x + 10, y), 6, style).into_dyn()
                } else {
                    PathElement::new(vec![(x, y), (x + 20, y)], style).into_dyn()
                }
            });
        }
    }
    if labelled {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FONT, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(120, 120, 120))
            .draw()
            .map_err(e)?;
    }
    Ok(())
}

/// Draws `fig` onto `root`.
fn draw_figure<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &Figure,
) -> Result<(), String> {
    if !font_ready() {
        return Err("the embedded DejaVu Sans font could not be loaded".to_owned());
    }
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let body = root.titled(&fig.title, (FONT, 19)).map_err(e)?;
    for (area, panel) in body.split_evenly((fig.panels.len().max(1), 1)).iter().zip(&fig.panels) {
        draw_panel(area, panel)?;
    }
    root.present().map_err(e)
}

/// Renders `fig` as SVG text.
fn render_svg(fig: &Figure) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, fig.size).into_drawing_area();
        draw_figure(&root, fig)?;
    }
    Ok(svg)
}

/// Renders `fig` as an RGB image.
fn render_rgb(fig: &Figure) -> Result<image::RgbImage, String> {
    let (w, h) = fig.size;
    let mut img = image::RgbImage::new(w, h);
    {
        let root = BitMapBackend::with_buffer(&mut img, (w, h)).into_drawing_area();
        draw_figure(&root, fig)?;
    }
    Ok(img)
}

/// Writes `fig` as `STEM.svg` and `STEM.png` (`stem` is a path without extension) and
/// returns both paths.
fn write_figure(stem: &Path, fig: &Figure) -> Result<Vec<PathBuf>, PlotError> {
    let svg_path = stem.with_extension("svg");
    let png_path = stem.with_extension("png");
    let svg =
        render_svg(fig).map_err(|message| PlotError::Draw { path: svg_path.clone(), message })?;
    let img =
        render_rgb(fig).map_err(|message| PlotError::Draw { path: png_path.clone(), message })?;
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png)
        .map_err(|source| PlotError::Image { path: png_path.clone(), source })?;
    for (path, bytes) in [(&svg_path, svg.as_bytes()), (&png_path, png.get_ref().as_slice())] {
        crate::run::stream::write_atomic_io(path, bytes)
            .map_err(|source| PlotError::Io { path: path.clone(), source })?;
    }
    Ok(vec![svg_path, png_path])
}

/// How an alignment is named in titles: `SE(3)`, `Sim(3)` or `none`.
pub fn align_name(align: Align) -> &'static str {
    match align {
        Align::None => "none",
        Align::Se3 => "SE(3)",
        Align::Sim3 => "Sim(3)",
    }
}

/// The part of a title that says how the estimate was aligned.
fn aligned_note(align: Align) -> String {
    match align {
        Align::None => "alignment: none (raw estimate)".to_owned(),
        a => format!("estimate {}-aligned to ground truth (Umeyama)", align_name(a)),
    }
}

/// `(x, z)` of every pose: the top view of a trajectory in KITTI camera coordinates
/// (x right, y down, z forward), metres.
pub fn top_view_xz(poses: &[Se3]) -> Vec<(f64, f64)> {
    poses.iter().map(|p| (p.trans.x, p.trans.z)).collect()
}

/// Roll, pitch and yaw (degrees) of a pose's rotation: the angles of nalgebra's
/// `Rotation3::euler_angles`, `R = Rz(yaw) · Ry(pitch) · Rx(roll)` about the world (first
/// camera) axes.
pub fn roll_pitch_yaw_deg(pose: &Se3) -> [f64; 3] {
    let (r, p, y) = nalgebra::Rotation3::from_matrix_unchecked(pose.rot).euler_angles();
    [r.to_degrees(), p.to_degrees(), y.to_degrees()]
}

/// A top-view panel: ground truth, the named estimates (each with its own colour) and a ring
/// at the start of the ground truth.
fn top_view_panel(gt: &[Se3], estimates: &[(String, Vec<Se3>)]) -> Panel {
    let mut series = vec![Series::line("ground truth", top_view_xz(gt), GT_COLOR)];
    for (k, (name, est)) in estimates.iter().enumerate() {
        series.push(Series::line(name.clone(), top_view_xz(est), PALETTE[k % PALETTE.len()]));
    }
    if let Some(first) = gt.first() {
        series.push(Series {
            name: "start".to_owned(),
            points: top_view_xz(&[*first]),
            color: RGBColor(0, 0, 0),
            mark: Mark::Ring,
        });
    }
    let mut panel = Panel::new("x [m]", "z [m]", series);
    panel.equal_aspect = true;
    panel
}

/// The x axis of the over-time plots: `times_s` when it covers every frame, else the frame
/// index.
fn time_axis(times_s: Option<&[f64]>, n: usize) -> (Vec<f64>, &'static str) {
    match times_s {
        Some(t) if t.len() >= n => (t[..n].to_vec(), "time [s]"),
        _ => ((0..n).map(|i| i as f64).collect(), "frame [index]"),
    }
}

/// Writes the figures of an evaluation into `dir` (created if needed), each as `NAME.svg` and
/// `NAME.png`, and returns their paths:
///
/// * `trajectory`: top view (x–z plane of the camera frame, m, equal axis scale) of `gt` and
///   the aligned estimate;
/// * `ate`: the ATE (translation error after the alignment, m) over ground-truth distance
///   travelled (m);
/// * `rpe`: RPE translation (m) and rotation (deg) over time, for each delta the evaluator uses
///   (1 frame, 10 m), plotted at the time of the pair's second pose;
/// * `position`: x, y, z (m) of the aligned estimate and the ground truth over time;
/// * `orientation`: roll, pitch, yaw (deg, [`roll_pitch_yaw_deg`]) over time, likewise;
/// * `per_length`: the KITTI devkit t_rel (%) and r_rel (deg/100 m) per segment length (m).
///
/// `times_s` is each frame's time (s); without it (or when it is shorter than the
/// trajectory) the over-time plots use the frame index.
pub fn write_eval_plots(
    dir: impl AsRef<Path>,
    gt: &[Se3],
    report: &EvalReport,
    times_s: Option<&[f64]>,
) -> Result<Vec<PathBuf>, PlotError> {
    let dir = dir.as_ref();
    std::fs::create_dir_all(dir)
        .map_err(|source| PlotError::Io { path: dir.to_path_buf(), source })?;
    let align = report.align;
    let note = aligned_note(align);
    let est = &report.aligned_est;
    let mut written = Vec::new();

    let summary = match (report.t_rel_pct, report.r_rel_deg_per_100m) {
        (Some(t), Some(r)) => format!(
            "ATE({}) {:.2} m, t_rel {t:.2} %, r_rel {r:.2} deg/100 m",
            align_name(align),
            report.ate_rmse_m
        ),
        _ => format!("ATE({}) {:.2} m", align_name(align), report.ate_rmse_m),
    };
    let top = Figure {
        title: format!("Top view; {note}; {summary}"),
        size: (900, 900),
        panels: vec![top_view_panel(gt, &[("estimate".to_owned(), est.clone())])],
    };
    written.extend(write_figure(&dir.join("trajectory"), &top)?);

    let ate_pts: Vec<(f64, f64)> =
        report.gt_distances_m.iter().copied().zip(report.ate_errors_m.iter().copied()).collect();
    let mut ate_panel = Panel::new(
        "distance travelled [m]",
        &format!("ATE ({} aligned) [m]", align_name(align)),
        vec![Series::line("", ate_pts, PALETTE[0])],
    );
    ate_panel.from_zero = true;
    let ate = Figure {
        title: format!(
            "ATE over distance; {note}; rmse {:.3} m, max {:.3} m",
            report.ate_rmse_m, report.ate_max_m
        ),
        size: (1100, 500),
        panels: vec![ate_panel],
    };
    written.extend(write_figure(&dir.join("ate"), &ate)?);

    let n = gt.len().min(est.len());
    let (t, xlabel) = time_axis(times_s, n);
    let at = |i: usize| t.get(i).copied().unwrap_or(f64::NAN);
    let mut trans = Vec::new();
    let mut rot = Vec::new();
    for (k, r) in [&report.rpe_1f, &report.rpe_10m].into_iter().flatten().enumerate() {
        let c = PALETTE[k + 1];
        let name = format!("over {}", r.delta);
        let tp = r.pairs.iter().zip(&r.trans_errors_m).map(|(&(_, j), &v)| (at(j), v)).collect();
        let rp = r.pairs.iter().zip(&r.rot_errors_deg).map(|(&(_, j), &v)| (at(j), v)).collect();
        trans.push(Series::line(name.clone(), tp, c));
        rot.push(Series::line(name, rp, c));
    }
    let mut rpe_panels = vec![
        Panel::new(xlabel, "RPE translation [m]", trans),
        Panel::new(xlabel, "RPE rotation [deg]", rot),
    ];
    for p in &mut rpe_panels {
        p.from_zero = true;
    }
    let rpe = Figure {
        title: format!(
            "RPE over time (relative poses: alignment none; the ATE of this evaluation uses {})",
            align_name(align)
        ),
        size: (1100, 760),
        panels: rpe_panels,
    };
    written.extend(write_figure(&dir.join("rpe"), &rpe)?);

    let over_time = |labels: [&str; 3], value: &dyn Fn(&Se3) -> [f64; 3]| -> Vec<Panel> {
        (0..3)
            .map(|axis| {
                let curve = |poses: &[Se3]| -> Vec<(f64, f64)> {
                    poses[..n].iter().enumerate().map(|(i, p)| (t[i], value(p)[axis])).collect()
                };
                Panel::new(
                    xlabel,
                    labels[axis],
                    vec![
                        Series::line("ground truth", curve(gt), GT_COLOR),
                        Series::line("estimate", curve(est), PALETTE[0]),
                    ],
                )
            })
            .collect()
    };
    let position = Figure {
        title: format!("Position over time (camera frame of the first pose); {note}"),
        size: (1100, 1000),
        panels: over_time(["x [m]", "y [m]", "z [m]"], &|p| [p.trans.x, p.trans.y, p.trans.z]),
    };
    written.extend(write_figure(&dir.join("position"), &position)?);
    let orientation = Figure {
        title: format!("Orientation over time (R = Rz(yaw) Ry(pitch) Rx(roll)); {note}"),
        size: (1100, 1000),
        panels: over_time(["roll [deg]", "pitch [deg]", "yaw [deg]"], &roll_pitch_yaw_deg),
    };
    written.extend(write_figure(&dir.join("orientation"), &orientation)?);

    let pl = &report.per_length;
    let mut t_rel =
        Series::line("t_rel", pl.iter().map(|r| (r.length_m, r.t_rel_pct)).collect(), PALETTE[0]);
    let mut r_rel = Series::line(
        "r_rel",
        pl.iter().map(|r| (r.length_m, r.r_rel_deg_per_100m)).collect(),
        PALETTE[1],
    );
    t_rel.mark = Mark::LinePoints;
    r_rel.mark = Mark::LinePoints;
    let mut length_panels = vec![
        Panel::new("segment length [m]", "t_rel [%]", vec![t_rel]),
        Panel::new("segment length [m]", "r_rel [deg/100 m]", vec![r_rel]),
    ];
    for p in &mut length_panels {
        p.from_zero = true;
    }
    let per_length = Figure {
        title: format!(
            "KITTI devkit errors per segment length ({}; relative errors: alignment none; the \
             ATE of this evaluation uses {})",
            if pl.is_empty() {
                "no segments: path < 100 m".to_owned()
            } else {
                format!("{} segments", report.n_segments)
            },
            align_name(align)
        ),
        size: (1100, 760),
        panels: length_panels,
    };
    written.extend(write_figure(&dir.join("per_length"), &per_length)?);
    Ok(written)
}

/// Writes one top view (x–z plane, m, equal axis scale) with the ground truth and every named
/// estimate overlaid, the legend naming each, as `STEM.svg` and `STEM.png`; returns both
/// paths. `estimates` are already aligned by `align` (named in the title).
pub fn write_overlay_top_view(
    stem: impl AsRef<Path>,
    gt: &[Se3],
    estimates: &[(String, Vec<Se3>)],
    align: Align,
    title: &str,
) -> Result<Vec<PathBuf>, PlotError> {
    let fig = Figure {
        title: format!("{title}; {}", aligned_note(align)),
        size: (1000, 1000),
        panels: vec![top_view_panel(gt, estimates)],
    };
    write_figure(stem.as_ref(), &fig)
}

/// Draws `text` into `img` in the embedded font, `size_px` high, its top-left corner at
/// `(x, y)` (clipped to the image). Does nothing when the font cannot be loaded.
pub fn draw_label(
    img: &mut image::RgbImage,
    x: i32,
    y: i32,
    text: &str,
    size_px: u32,
    rgb: [u8; 3],
) {
    if !font_ready() {
        return;
    }
    let (w, h) = img.dimensions();
    let root = BitMapBackend::with_buffer(img, (w, h)).into_drawing_area();
    let color = RGBColor(rgb[0], rgb[1], rgb[2]);
    let style = TextStyle::from((FONT, size_px)).color(&color);
    let _ = root.draw_text(text, &style, (x, y));
    let _ = root.present();
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nonwhite(img: &image::RgbImage) -> usize {
        img.pixels().filter(|p| p.0 != [255, 255, 255]).count()
    }

    fn fig(points: &[(f64, f64)]) -> Figure {
        Figure {
            title: "t".to_owned(),
            size: (400, 300),
            panels: vec![Panel::new(
                "x [m]",
                "y [m]",
                vec![Series::line("s", points.to_vec(), GT_COLOR)],
            )],
        }
    }

    #[test]
    fn degenerate_inputs_give_pictures() {
        let cases: [&[(f64, f64)]; 5] = [
            &[],
            &[(1.0, 2.0)],
            &[(3.0, 3.0); 10],
            &[(f64::NAN, 0.0), (1.0, f64::INFINITY), (0.0, 0.0), (1e12, -1e12)],
            &[(0.0, 0.0), (0.0, 100.0)],
        ];
        for pts in cases {
            let img = render_rgb(&fig(pts)).unwrap();
            assert!(nonwhite(&img) > 500, "{pts:?}");
            let svg = render_svg(&fig(pts)).unwrap();
            roxmltree::Document::parse(&svg).unwrap();
        }
    }

    #[test]
    fn unwritable_path_is_an_error_naming_it() {
        let e = write_figure(Path::new("/nonexistent-dir/x"), &fig(&[(0.0, 0.0), (1.0, 1.0)]))
            .unwrap_err();
        assert!(e.to_string().contains("/nonexistent-dir/x."), "{e}");
    }

    #[test]
    fn equal_aspect_gives_one_scale() {
        let (x, y) = equal_aspect((0.0, 10.0), (0.0, 100.0), 400.0, 200.0);
        let (ux, uy) = ((x.1 - x.0) / 400.0, (y.1 - y.0) / 200.0);
        assert!((ux - uy).abs() < 1e-12 && (uy - 0.5).abs() < 1e-12, "{x:?} {y:?}");
        assert!((x.0 + x.1 - 10.0).abs() < 1e-9, "centre kept");
        assert_eq!(range_of([f64::NAN].into_iter(), 0.1), (-1.0, 1.0));
        assert_eq!(range_of([2.0, 2.0].into_iter(), 0.1), (1.0, 3.0));
    }

    #[test]
    fn roll_pitch_yaw_of_a_yaw() {
        let p = Se3::new(
            nalgebra::Rotation3::from_euler_angles(0.1, -0.2, 0.3).into_inner(),
            nalgebra::Vector3::zeros(),
        );
        let [r, pi, y] = roll_pitch_yaw_deg(&p);
        assert!((r - 0.1f64.to_degrees()).abs() < 1e-9);
        assert!((pi + 0.2f64.to_degrees()).abs() < 1e-9);
        assert!((y - 0.3f64.to_degrees()).abs() < 1e-9);
    }

    /// A quarter circle of 400 poses turning about y, and an estimate 2 % too long.
    fn arc() -> (Vec<Se3>, Vec<Se3>) {
        use nalgebra::{Rotation3, Vector3};
        let gt: Vec<Se3> = (0..400)
            .map(|i| {
                let a = f64::from(i) * 0.004;
                Se3::new(
                    Rotation3::from_euler_angles(0.0, a, 0.0).into_inner(),
                    Vector3::new(100.0 * (1.0 - a.cos()), 0.0, 100.0 * a.sin()),
                )
            })
            .collect();
        let est = gt.iter().map(|p| Se3::new(p.rot, p.trans * 1.02)).collect();
        (gt, est)
    }

    /// The text of every `<text>` element of a well-formed SVG of `size` px.
    fn svg_texts(path: &Path, size: (u32, u32)) -> Vec<String> {
        let text = std::fs::read_to_string(path).unwrap();
        let doc = roxmltree::Document::parse(&text)
            .unwrap_or_else(|e| panic!("{}: not XML: {e}", path.display()));
        let root = doc.root_element();
        assert_eq!(root.tag_name().name(), "svg");
        assert_eq!(root.attribute("width"), Some(size.0.to_string().as_str()));
        assert_eq!(root.attribute("height"), Some(size.1.to_string().as_str()));
        doc.descendants()
            .filter(|n| n.has_tag_name("text"))
            .filter_map(|n| n.text().map(|t| t.trim().to_owned()))
            .collect()
    }

    /// Decodes a PNG, checks its size, that it is far from blank and has pixels of `colour`.
    fn check_png(path: &Path, size: (u32, u32), colour: RGBColor) {
        let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!((img.width(), img.height()), size, "{}", path.display());
        let img = img.to_rgb8();
        let coloured = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
        assert!(coloured > 5000, "{}: {coloured} non-white pixels", path.display());
        let c = img.pixels().filter(|p| p.0 == [colour.0, colour.1, colour.2]).count();
        assert!(c > 50, "{}: series colour missing ({c} px)", path.display());
    }

    #[test]
    fn eval_plots_are_valid_svg_and_png_with_their_series() {
        use crate::eval::evaluate;
        let (gt, est) = arc();
        let times: Vec<f64> = (0..gt.len()).map(|i| 0.1 * i as f64).collect();
        let dir = tempfile::tempdir().unwrap();
        for align in [Align::Se3, Align::Sim3, Align::None] {
            let r = evaluate(&gt, &est, align).unwrap();
            let files = write_eval_plots(dir.path(), &gt, &r, Some(&times)).unwrap();
            assert_eq!(files.len(), 12);
            let expect: [(&str, (u32, u32), &[&str]); 6] = [
                (
                    "trajectory",
                    (900, 900),
                    &["ground truth", "estimate", "start", "x [m]", "z [m]"],
                ),
                ("ate", (1100, 500), &["distance travelled [m]"]),
                (
                    "rpe",
                    (1100, 760),
                    &["over 1 frame", "over 10 m", "time [s]", "RPE rotation [deg]"],
                ),
                ("position", (1100, 1000), &["ground truth", "estimate", "y [m]"]),
                ("orientation", (1100, 1000), &["ground truth", "estimate", "yaw [deg]"]),
                ("per_length", (1100, 760), &["t_rel", "r_rel", "segment length [m]"]),
            ];
            for (name, size, series) in expect {
                let texts = svg_texts(&dir.path().join(format!("{name}.svg")), size);
                for s in series {
                    assert!(texts.iter().any(|t| t == s), "{name}.svg lacks {s:?}: {texts:?}");
                }
                let title = &texts[0];
                let named = match align {
                    Align::None => {
                        title.contains("alignment: none") || title.contains("alignment none")
                    }
                    a => title.contains(align_name(a)),
                };
                assert!(named, "{name}.svg's title does not name the {align} alignment: {title}");
                let colour = if name == "rpe" { PALETTE[1] } else { PALETTE[0] };
                check_png(&dir.path().join(format!("{name}.png")), size, colour);
            }
            let names: Vec<_> =
                std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
            assert!(!names.iter().any(|n| n.to_string_lossy().ends_with(".tmp")), "{names:?}");
        }
    }

    #[test]
    fn overlay_names_every_row() {
        let (gt, est) = arc();
        let rows: Vec<(String, Vec<Se3>)> = ["off-hard", "cull-em", "full-hard", "motion-em"]
            .iter()
            .enumerate()
            .map(|(k, n)| {
                let f = 1.0 + 0.01 * k as f64;
                ((*n).to_owned(), est.iter().map(|p| Se3::new(p.rot, p.trans * f)).collect())
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let stem = dir.path().join("trajectories");
        let files = write_overlay_top_view(&stem, &gt, &rows, Align::Sim3, "ablation").unwrap();
        assert_eq!(files, vec![stem.with_extension("svg"), stem.with_extension("png")]);
        let texts = svg_texts(&files[0], (1000, 1000));
        for (name, _) in &rows {
            assert!(texts.iter().any(|t| t == name), "{name} missing from {texts:?}");
        }
        assert!(texts[0].contains("Sim(3)"), "{}", texts[0]);
        for colour in &PALETTE[..4] {
            check_png(&files[1], (1000, 1000), *colour);
        }
    }

    #[test]
    fn label_is_drawn() {
        let mut img = image::RgbImage::from_pixel(120, 20, image::Rgb([255, 255, 255]));
        draw_label(&mut img, 2, 2, "road", 13, [0, 0, 0]);
        assert!(nonwhite(&img) > 20);
    }
}
