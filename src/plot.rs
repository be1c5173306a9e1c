//! Error-curve figures: RE/EE/ME against time on log axes, one column per
//! system, one line per model with its shaded 95% band (as in the paper's
//! figures).

use std::path::Path;
use std::sync::OnceLock;

use crate::error::{bail, err, Context};
use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::metrics::{Band, Summary, DIVERGED, LOG_FLOOR};

/// DejaVu Sans, embedded so text renders without system fonts (license in
/// assets/LICENSE-DejaVu.txt).
const FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

/// A failure of plotters on a PNG bitmap.
type DrawError = DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>;

crate::error::typed_errors!(DrawError);

/// Pixels per panel.
const CELL: (u32, u32) = (460, 300);

/// Registers the embedded font with plotters once per process.
fn ensure_font() -> crate::error::Result<()> {
    static LOADED: OnceLock<bool> = OnceLock::new();
    let loaded = *LOADED
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if loaded {
        Ok(())
    } else {
        Err(err!("the embedded DejaVu Sans font could not be loaded"))
    }
}

/// Line colours, distinguishable and print-friendly.
const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// Selects one metric's band from a summary.
type Pick = fn(&Summary) -> &Band;

/// A metric a figure row can show.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Metric {
    /// Relative rollout error RE(t).
    Re,
    /// Energy violation error EE(t).
    Ee,
    /// Momentum error ME(t) (paper definition).
    Me,
    /// Momentum error relative to the momentum scale.
    MeScaled,
    /// Absolute rollout error ‖q̂ − q‖.
    ReAbs,
    /// Absolute momentum error ‖P̂ − P‖.
    MeAbs,
}

impl Metric {
    /// Axis label.
    pub fn label(self) -> &'static str {
        match self {
            Metric::Re => "RE(t)",
            Metric::Ee => "EE(t)",
            Metric::Me => "ME(t)",
            Metric::MeScaled => "ME scaled",
            Metric::ReAbs => "|q̂ − q|",
            Metric::MeAbs => "|P̂ − P|",
        }
    }

    fn pick(self) -> Pick {
        match self {
            Metric::Re => |s| &s.re,
            Metric::Ee => |s| &s.ee,
            Metric::Me => |s| &s.me,
            Metric::MeScaled => |s| &s.me_scaled,
            Metric::ReAbs => |s| &s.re_abs,
            Metric::MeAbs => |s| &s.me_abs,
        }
    }
}

/// The rows of [`plot_summaries`].
const ROWS: [Metric; 4] = [Metric::Re, Metric::Ee, Metric::Me, Metric::MeScaled];

/// A tick label: at most 3 decimals, no trailing zeros ("0.3", not
/// "0.30000000000000004").
fn tick(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}

/// Smallest and largest positive (non-floored) value of a row, padded to
/// whole decades; (1e-16, 1) when everything is zero.
fn y_range(models: &[(String, Summary)], pick: Pick) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0_f64);
    for (_, s) in models {
        let b = pick(s);
        for &x in b.lo.iter().chain(&b.hi).chain(&b.gmean) {
            // Floored zeros and diverged stand-ins would stretch the axis
            // to 1e±300; they are drawn clamped at its edge instead.
            if x.is_finite() && x > LOG_FLOOR * 10.0 && x < DIVERGED / 10.0 {
                lo = lo.min(x);
                hi = hi.max(x);
            }
        }
    }
    if !lo.is_finite() {
        return (1e-16, 1.0);
    }
    // Keep the axis within ~20 decades so a stray tiny value cannot squash it.
    let lo = lo.max(hi * 1e-20);
    let (lo, hi) = (
        10f64.powf(lo.log10().floor()),
        10f64.powf(hi.log10().ceil()),
    );
    if hi <= lo {
        (lo / 10.0, hi * 10.0)
    } else {
        (lo, hi)
    }
}

/// Writes one PNG: rows RE/EE/ME/ME-scaled (log y), a column per panel (e.g. "5-spring"),
/// each model a line (geometric mean) with a shaded 95% band and a legend.
///
/// Errors on empty input, summaries whose bands do not match their times, or
/// when the file cannot be written.
pub fn plot_summaries(
    path: &Path,
    panels: &[(String, Vec<(String, Summary)>)],
) -> crate::error::Result<()> {
    plot_metrics(path, panels, &ROWS)
}

/// [`plot_summaries`] with a chosen list of rows.
pub fn plot_metrics(
    path: &Path,
    panels: &[(String, Vec<(String, Summary)>)],
    rows: &[Metric],
) -> crate::error::Result<()> {
    if rows.is_empty() {
        bail!("nothing to plot: no metrics");
    }
    if panels.is_empty() {
        bail!("nothing to plot: no panels");
    }
    for (title, models) in panels {
        if models.is_empty() {
            bail!("panel {title:?} has no models");
        }
        for (name, s) in models {
            let n = s.t.len();
            let ok = n > 0
                && rows
                    .iter()
                    .map(|m| m.pick()(s))
                    .all(|b| b.gmean.len() == n && b.lo.len() == n && b.hi.len() == n);
            if !ok {
                bail!(
                    "panel {title:?}, model {name:?}: empty summary or bands of the wrong length"
                );
            }
        }
    }
    ensure_font()?;
    let size = (CELL.0 * panels.len() as u32, CELL.1 * rows.len() as u32);
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)?;
    let cells = root.split_evenly((rows.len(), panels.len()));
    let mut names: Vec<&str> = vec![];
    for (name, _) in panels.iter().flat_map(|p| &p.1) {
        if !names.contains(&name.as_str()) {
            names.push(name);
        }
    }
    for (r, m) in rows.iter().enumerate() {
        let (label, pick) = (m.label(), m.pick());
        for (c, (title, models)) in panels.iter().enumerate() {
            let area = &cells[r * panels.len() + c];
            draw_cell(
                area,
                (title, label),
                pick,
                models,
                &names,
                r == 0,
                r + 1 == rows.len(),
            )
            .with_context(|| format!("drawing {label} of {title}"))?;
        }
    }
    root.present()
        .with_context(|| format!("writing plot {}", path.display()))?;
    Ok(())
}

/// `names`: every model of the figure, in order; a model keeps its colour
/// across panels.
fn draw_cell(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    (title, label): (&str, &str),
    pick: Pick,
    models: &[(String, Summary)],
    names: &[&str],
    top: bool,
    bottom: bool,
) -> crate::error::Result<()> {
    let t0 = models
        .iter()
        .map(|m| m.1.t[0])
        .fold(f64::INFINITY, f64::min);
    let mut t1 = models
        .iter()
        .map(|m| *m.1.t.last().unwrap_or(&t0))
        .fold(f64::NEG_INFINITY, f64::max);
    if t1 <= t0 {
        t1 = t0 + 1.0;
    }
    let (ylo, yhi) = y_range(models, pick);
    let clamp = |y: f64| y.clamp(ylo, yhi);
    let mut builder = ChartBuilder::on(area);
    builder
        .margin(8)
        .x_label_area_size(if bottom { 40 } else { 22 })
        .y_label_area_size(62);
    if top {
        builder.caption(title, (FAMILY, 20));
    }
    let mut chart = builder.build_cartesian_2d(t0..t1, (ylo..yhi).log_scale())?;
    let mut mesh = chart.configure_mesh();
    mesh.y_desc(label)
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .x_label_formatter(&|v| tick(*v))
        .label_style((FAMILY, 13))
        .axis_desc_style((FAMILY, 15))
        .light_line_style(WHITE.mix(0.0));
    if bottom {
        mesh.x_desc("time (s)");
    }
    mesh.draw()?;
    for (name, s) in models {
        let i = names.iter().position(|n| n == name).unwrap_or(0);
        let color = COLORS[i % COLORS.len()];
        let b = pick(s);
        let mut poly: Vec<(f64, f64)> =
            s.t.iter()
                .zip(&b.lo)
                .map(|(t, y)| (*t, clamp(*y)))
                .collect();
        poly.extend(s.t.iter().zip(&b.hi).rev().map(|(t, y)| (*t, clamp(*y))));
        chart.draw_series(std::iter::once(Polygon::new(
            poly,
            color.mix(0.18).filled(),
        )))?;
        chart
            .draw_series(LineSeries::new(
                s.t.iter().zip(&b.gmean).map(|(t, y)| (*t, clamp(*y))),
                color.stroke_width(2),
            ))?
            .label(name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
    }
    if top {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.5))
            .label_font((FAMILY, 13))
            .draw()?;
    }
    Ok(())
}

/// One model's line in a sweep figure: (x, geometric mean, band low, band high).
pub type SweepLine = (String, Vec<(f64, f64, f64, f64)>);

/// A sweep figure (errors against noise level or data size): one panel per
/// entry of `panels` (title, y label, lines), log y, log x when `log_x`,
/// each model a line with markers and a shaded band.
pub fn plot_sweep(
    path: &Path,
    x_label: &str,
    log_x: bool,
    panels: &[(String, String, Vec<SweepLine>)],
) -> crate::error::Result<()> {
    if panels.is_empty() || panels.iter().any(|p| p.2.iter().all(|l| l.1.is_empty())) {
        bail!("nothing to plot: a sweep panel has no points");
    }
    ensure_font()?;
    let root =
        BitMapBackend::new(path, (CELL.0 * panels.len() as u32, CELL.1 + 40)).into_drawing_area();
    root.fill(&WHITE)?;
    let cells = root.split_evenly((1, panels.len()));
    for ((title, y_label, lines), area) in panels.iter().zip(&cells) {
        draw_sweep(area, title, y_label, x_label, log_x, lines)
            .with_context(|| format!("drawing sweep panel {title}"))?;
    }
    root.present()
        .with_context(|| format!("writing plot {}", path.display()))?;
    Ok(())
}

fn draw_sweep(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    title: &str,
    y_label: &str,
    x_label: &str,
    log_x: bool,
    lines: &[SweepLine],
) -> crate::error::Result<()> {
    let (ylo, yhi) = sweep_y_range(lines);
    let (x0, x1) = sweep_x_range(lines, log_x);
    let pad = 0.05 * (x1 - x0);
    let tx = move |x: f64| if log_x { x.max(1e-300).log10() } else { x };
    let clamp = |y: f64| y.clamp(ylo, yhi);
    let mut chart = ChartBuilder::on(area)
        .margin(8)
        .caption(title, (FAMILY, 18))
        .x_label_area_size(40)
        .y_label_area_size(62)
        .build_cartesian_2d((x0 - pad)..(x1 + pad), (ylo..yhi).log_scale())?;
    let x_ticks = |v: &f64| sweep_x_tick(*v, log_x);
    let mut mesh = chart.configure_mesh();
    mesh.y_desc(y_label)
        .x_desc(x_label)
        .y_label_formatter(&|v| format!("{v:.0e}"))
        // On a log axis only whole decades are labelled (plotters places
        // ticks at round numbers of log10 x, among them the integers), and
        // its many ticks get no grid lines.
        .x_labels(if log_x { 40 } else { 10 })
        .x_label_formatter(&x_ticks)
        .label_style((FAMILY, 13))
        .axis_desc_style((FAMILY, 15))
        .light_line_style(WHITE.mix(0.0));
    if log_x {
        mesh.disable_x_mesh();
    }
    mesh.draw()?;
    for (i, (name, p)) in lines.iter().enumerate() {
        if p.is_empty() {
            continue;
        }
        let color = COLORS[i % COLORS.len()];
        let mut poly: Vec<(f64, f64)> = p.iter().map(|q| (tx(q.0), clamp(q.2))).collect();
        poly.extend(p.iter().rev().map(|q| (tx(q.0), clamp(q.3))));
        chart.draw_series(std::iter::once(Polygon::new(
            poly,
            color.mix(0.15).filled(),
        )))?;
        chart
            .draw_series(LineSeries::new(
                p.iter().map(|q| (tx(q.0), clamp(q.1))),
                color.stroke_width(2),
            ))?
            .label(name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
        chart.draw_series(
            p.iter()
                .map(|q| Circle::new((tx(q.0), clamp(q.1)), 4, color.filled())),
        )?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.5))
        .label_font((FAMILY, 13))
        .draw()?;
    Ok(())
}

/// The log y axis of a sweep panel: whole decades around every usable
/// value (finite, above the floor, below divergence) of its points and
/// bands; 1e-16..1 when there is none.
fn sweep_y_range(lines: &[SweepLine]) -> (f64, f64) {
    let usable = |y: f64| y.is_finite() && y > LOG_FLOOR * 10.0 && y < DIVERGED / 10.0;
    let (mut ylo, mut yhi) = (f64::INFINITY, 0.0_f64);
    for p in lines.iter().flat_map(|l| l.1.iter()) {
        for y in [p.1, p.2, p.3] {
            if usable(y) {
                ylo = ylo.min(y);
                yhi = yhi.max(y);
            }
        }
    }
    if !ylo.is_finite() {
        (ylo, yhi) = (1e-16, 1.0);
    }
    let ylo = 10f64.powf(ylo.max(yhi * 1e-20).log10().floor());
    let mut yhi = 10f64.powf(yhi.log10().ceil());
    if yhi <= ylo {
        yhi = ylo * 10.0;
    }
    (ylo, yhi)
}

/// The x extent of a sweep panel's points (log10 x when `log_x`), at least
/// 1 wide.
fn sweep_x_range(lines: &[SweepLine], log_x: bool) -> (f64, f64) {
    let xs = || {
        lines
            .iter()
            .flat_map(|l| l.1.iter())
            .map(|p| if log_x { p.0.max(1e-300).log10() } else { p.0 })
    };
    let x0 = xs().fold(f64::INFINITY, f64::min);
    let mut x1 = xs().fold(f64::NEG_INFINITY, f64::max);
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    (x0, x1)
}

/// The label of the x tick at `v`: on a log axis, only whole decades.
fn sweep_x_tick(v: f64, log_x: bool) -> String {
    if !log_x {
        tick(v)
    } else if (v - v.round()).abs() < 1e-6 {
        format!("{}", 10f64.powf(v.round()))
    } else {
        String::new()
    }
}

/// A 3D scene of coloured primitives (what a `visualization_msgs/MarkerArray`
/// draws), for [`draw_scene`]. Sizes are in scene units.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// Title above the picture.
    pub title: String,
    /// Line segments: ends, colour, width.
    pub segments: Vec<([f64; 3], [f64; 3], RGBColor, f64)>,
    /// Discs (spheres): centre, colour, diameter.
    pub discs: Vec<([f64; 3], RGBColor, f64)>,
    /// Squares (cubes): centre, colour, side.
    pub squares: Vec<([f64; 3], RGBColor, f64)>,
    /// Arrows: tail, head, colour, shaft width.
    pub arrows: Vec<([f64; 3], [f64; 3], RGBColor, f64)>,
}

/// Draws `scene` to a PNG: seen along z when it is flat, else from an oblique
/// viewpoint (rotated 35° about z, then tilted 30°), scaled to fit with equal
/// axes; segments first, then squares, discs and arrows on top.
pub fn draw_scene(path: &Path, scene: &Scene) -> crate::error::Result<()> {
    ensure_font()?;
    let frame = Frame::fit(scene)?;
    let (to_px, px) = (|p| frame.to_px(p), |len| frame.px(len));
    let root = BitMapBackend::new(path, (frame.w, frame.h)).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| err!("drawing {}: {e}", path.display());
    root.fill(&WHITE).map_err(|e| err(&e))?;
    root.draw(&Text::new(
        scene.title.clone(),
        (20, 15),
        (FAMILY, 20).into_font().color(&BLACK),
    ))
    .map_err(|e| err(&e))?;
    for (a, b, c, width) in &scene.segments {
        let style = c.stroke_width(px(*width));
        root.draw(&PathElement::new(vec![to_px(*a), to_px(*b)], style))
            .map_err(|e| err(&e))?;
    }
    for (p, c, side) in &scene.squares {
        let (x, y) = to_px(*p);
        let r = (px(*side) / 2).max(2) as i32;
        root.draw(&Rectangle::new(
            [(x - r, y - r), (x + r, y + r)],
            c.filled(),
        ))
        .map_err(|e| err(&e))?;
    }
    for (p, c, d) in &scene.discs {
        root.draw(&Circle::new(to_px(*p), (px(*d) / 2).max(2), c.filled()))
            .map_err(|e| err(&e))?;
        root.draw(&Circle::new(
            to_px(*p),
            (px(*d) / 2).max(2),
            BLACK.stroke_width(1),
        ))
        .map_err(|e| err(&e))?;
    }
    for (a, b, c, width) in &scene.arrows {
        draw_arrow(&root, to_px(*a), to_px(*b), *c, px(*width).max(2)).map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

/// Where a [`Scene`] lands on the picture: the view (rotation about z, then
/// about x) and the scale and offset that fit it with equal axes.
struct Frame {
    /// cos and sin of the rotation about z, then about x.
    cz: f64,
    sz: f64,
    cx: f64,
    sx: f64,
    /// Projected bounds of the scene's points.
    lo: (f64, f64),
    hi: (f64, f64),
    /// Pixels per scene unit.
    k: f64,
    /// Picture size, side and top margins in pixels.
    w: u32,
    h: u32,
    margin: f64,
    top: f64,
}

impl Frame {
    /// The frame of `scene`: seen along z when it is flat, else rotated 35°
    /// about z and tilted 30°; refuses a scene without points.
    fn fit(scene: &Scene) -> crate::error::Result<Frame> {
        let flat = scene
            .segments
            .iter()
            .flat_map(|s| [s.0, s.1])
            .chain(scene.discs.iter().map(|d| d.0))
            .all(|p| p[2] == 0.0);
        let (cz, sz, cx, sx) = if flat {
            (1.0, 0.0, 1.0, 0.0)
        } else {
            let (a, b) = (35f64.to_radians(), 60f64.to_radians());
            (a.cos(), a.sin(), b.cos(), b.sin())
        };
        let (w, h, margin, top) = (900u32, 800u32, 40.0, 50.0);
        let mut frame = Frame {
            cz,
            sz,
            cx,
            sx,
            lo: (f64::MAX, f64::MAX),
            hi: (f64::MIN, f64::MIN),
            k: 0.0,
            w,
            h,
            margin,
            top,
        };
        let pts: Vec<(f64, f64)> = scene
            .segments
            .iter()
            .flat_map(|s| [s.0, s.1])
            .chain(scene.discs.iter().map(|d| d.0))
            .chain(scene.squares.iter().map(|d| d.0))
            .chain(scene.arrows.iter().flat_map(|a| [a.0, a.1]))
            .map(|p| frame.project(p))
            .collect();
        if pts.is_empty() {
            bail!("nothing to draw: the markers hold no points");
        }
        for &(x, y) in &pts {
            frame.lo = (frame.lo.0.min(x), frame.lo.1.min(y));
            frame.hi = (frame.hi.0.max(x), frame.hi.1.max(y));
        }
        let (lo, hi) = (frame.lo, frame.hi);
        let span = (hi.0 - lo.0).max(hi.1 - lo.1).max(1e-12);
        frame.k = ((f64::from(w) - 2.0 * margin).min(f64::from(h) - margin - top)) / span;
        Ok(frame)
    }

    /// Rotates `p` about z, then about x; keeps (x, y) of the result.
    fn project(&self, p: [f64; 3]) -> (f64, f64) {
        let (x, y) = (
            self.cz * p[0] - self.sz * p[1],
            self.sz * p[0] + self.cz * p[1],
        );
        (x, self.cx * y - self.sx * p[2])
    }

    /// The pixel of the scene point `p`.
    fn to_px(&self, p: [f64; 3]) -> (i32, i32) {
        let (x, y) = self.project(p);
        let (lo, hi, k) = (self.lo, self.hi, self.k);
        let (w, h, margin, top) = (self.w, self.h, self.margin, self.top);
        let cx = f64::from(w) / 2.0 + k * (x - f64::midpoint(lo.0, hi.0));
        let cy = top + (f64::from(h) - margin - top) / 2.0 - k * (y - f64::midpoint(lo.1, hi.1));
        (cx.round() as i32, cy.round() as i32)
    }

    /// A length in scene units as whole pixels, at least 1.
    fn px(&self, len: f64) -> u32 {
        ((self.k * len).round() as u32).max(1)
    }
}

/// Draws an arrow from pixel `(x0, y0)` to `(x1, y1)`: a shaft `width`
/// pixels wide, and a filled head when it is at least 4 pixels long.
fn draw_arrow(
    root: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    (x0, y0): (i32, i32),
    (x1, y1): (i32, i32),
    c: RGBColor,
    width: u32,
) -> Result<(), DrawError> {
    let style = c.stroke_width(width);
    root.draw(&PathElement::new(vec![(x0, y0), (x1, y1)], style))?;
    let (dx, dy) = (f64::from(x1 - x0), f64::from(y1 - y0));
    let len = dx.hypot(dy);
    if len >= 4.0 {
        let (ux, uy) = (dx / len, dy / len);
        let head = (0.3 * len).min(12.0);
        let wing = |s: f64| {
            (
                (f64::from(x1) - head * ux + s * 0.5 * head * uy).round() as i32,
                (f64::from(y1) - head * uy - s * 0.5 * head * ux).round() as i32,
            )
        };
        root.draw(&Polygon::new(
            vec![(x1, y1), wing(1.0), wing(-1.0)],
            c.filled(),
        ))?;
    }
    Ok(())
}
