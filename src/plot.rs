//! Error-curve figures: RE/EE/ME against time on log axes, one column per
//! system, one line per model with its shaded 95% band (as in the paper's
//! figures).

use std::path::Path;
use std::sync::OnceLock;

use anyhow::{anyhow, bail, Context};
use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::metrics::{Band, Summary, LOG_FLOOR};

/// DejaVu Sans, embedded so text renders without system fonts (license in
/// assets/LICENSE-DejaVu.txt).
const FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

/// Pixels per panel.
const CELL: (u32, u32) = (460, 300);

/// Registers the embedded font with plotters once per process.
fn ensure_font() -> anyhow::Result<()> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
            .map_err(|_| "the embedded DejaVu Sans font could not be loaded".to_string())
    })
    .clone()
    .map_err(|e| anyhow!(e))
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

/// The rows of the figure: label and the band it plots.
const ROWS: [(&str, Pick); 4] = [
    ("RE(t)", |s| &s.re),
    ("EE(t)", |s| &s.ee),
    ("ME(t)", |s| &s.me),
    ("ME scaled", |s| &s.me_scaled),
];

/// Smallest and largest positive (non-floored) value of a row, padded to
/// whole decades; (1e-16, 1) when everything is zero.
fn y_range(models: &[(String, Summary)], pick: Pick) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0_f64);
    for (_, s) in models {
        let b = pick(s);
        for &x in b.lo.iter().chain(&b.hi).chain(&b.gmean) {
            if x.is_finite() && x > LOG_FLOOR * 10.0 {
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
) -> anyhow::Result<()> {
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
                && [&s.re, &s.ee, &s.me]
                    .iter()
                    .all(|b| b.gmean.len() == n && b.lo.len() == n && b.hi.len() == n);
            if !ok {
                bail!(
                    "panel {title:?}, model {name:?}: empty summary or bands of the wrong length"
                );
            }
        }
    }
    ensure_font()?;
    let size = (CELL.0 * panels.len() as u32, CELL.1 * ROWS.len() as u32);
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)?;
    let cells = root.split_evenly((ROWS.len(), panels.len()));
    for (r, (label, pick)) in ROWS.iter().enumerate() {
        for (c, (title, models)) in panels.iter().enumerate() {
            let area = &cells[r * panels.len() + c];
            draw_cell(
                area,
                title,
                label,
                *pick,
                models,
                r == 0,
                r + 1 == ROWS.len(),
            )
            .with_context(|| format!("drawing {label} of {title}"))?;
        }
    }
    root.present()
        .with_context(|| format!("writing plot {}", path.display()))?;
    Ok(())
}

fn draw_cell(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    title: &str,
    label: &str,
    pick: Pick,
    models: &[(String, Summary)],
    top: bool,
    bottom: bool,
) -> anyhow::Result<()> {
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
        .x_label_formatter(&|v| format!("{v}"))
        .label_style((FAMILY, 13))
        .axis_desc_style((FAMILY, 15))
        .light_line_style(WHITE.mix(0.0));
    if bottom {
        mesh.x_desc("time (s)");
    }
    mesh.draw()?;
    for (i, (name, s)) in models.iter().enumerate() {
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
