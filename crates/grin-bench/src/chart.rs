//! Error-against-cost charts (plotters): log-log, one curve per method (colour = integrator,
//! line = step policy), the Pareto front in black, and the method to use at each error
//! decade numbered on it. The legends (a swatch per integrator, a line sample per step
//! policy) and the numbered notes sit in a panel beside the plot, never over the data.
//! Drawn once for SVG and once for PNG.

use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;

/// One curve: a method's runs, cost ascending.
#[derive(Debug, Clone)]
pub struct Curve {
    pub label: String,
    /// Index into the integrator palette.
    pub color: usize,
    pub style: LineKind,
    /// (cost, error) pairs.
    pub points: Vec<(f64, f64)>,
}

/// Line style of a curve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineKind {
    Solid,
    Dashed,
    Dotted,
    /// A wide solid line (the accuracy knob's curves).
    Thick,
    /// Long dashes (the paper's method: its heuristic with its bisection exit).
    LongDash,
}

/// A chart's content.
#[derive(Debug, Clone)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub curves: Vec<Curve>,
    /// The Pareto front (cost, error).
    pub front: Vec<(f64, f64)>,
    /// Notes at (cost, error): the method named per decade (a number on the plot, the
    /// text beside it).
    pub notes: Vec<(f64, f64, String)>,
    /// What each colour is (palette index, name), and each line style.
    pub colors: Vec<(usize, String)>,
    pub styles: Vec<(LineKind, String)>,
}

const PALETTE: [RGBColor; 7] = [
    RGBColor(214, 39, 40),
    RGBColor(255, 127, 14),
    RGBColor(188, 160, 34),
    RGBColor(44, 160, 44),
    RGBColor(31, 119, 180),
    RGBColor(148, 103, 189),
    // `auto` (the pilot rays' choice): its own colour, after the six integrators.
    RGBColor(23, 190, 207),
];

/// Fonts searched for the chart text (Debian's fonts-dejavu-core first).
const FONT_PATHS: [&str; 3] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
];

/// Register a TrueType font for chart text (once per process).
pub fn ensure_font() -> anyhow::Result<()> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        let path = FONT_PATHS
            .iter()
            .find(|p| std::path::Path::new(p).exists())
            .ok_or_else(|| {
                format!(
                    "no font for chart text: none of {} exists (install fonts-dejavu-core; scripts/setup.sh does)",
                    FONT_PATHS.join(", ")
                )
            })?;
        let bytes = std::fs::read(path).map_err(|e| format!("{path}: {e}"))?;
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| format!("{path}: not a usable TrueType font"))
    })
    .clone()
    .map_err(anyhow::Error::msg)
}

fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow::Error::msg(format!("drawing the chart: {e}"))
}

/// Axis range of positive values, padded to whole decades.
fn decades(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for v in values.filter(|v| v.is_finite() && *v > 0.0) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (1e-16, 1.0);
    }
    (
        10f64.powf(lo.log10().floor()),
        10f64.powf(hi.log10().ceil().max(lo.log10().floor() + 1.0)),
    )
}

/// Smallest error drawn (errors of exactly 0 sit on the axis).
pub const ERROR_FLOOR: f64 = 1e-16;

/// Width of the panel beside the plot (legends and notes), pixels.
pub const PANEL_WIDTH: u32 = 400;

/// A line segment from (x0, y) to (x1, y) in `style` on a panel (pixel coordinates).
fn sample_line<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    (x0, x1, y): (i32, i32, i32),
    kind: LineKind,
    color: RGBColor,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let (on, off, width) = match kind {
        LineKind::Solid => (x1 - x0, 0, 2),
        LineKind::Dashed => (8, 5, 2),
        LineKind::Dotted => (2, 4, 2),
        LineKind::Thick => (x1 - x0, 0, 4),
        LineKind::LongDash => (14, 4, 2),
    };
    let mut x = x0;
    while x < x1 {
        let end = (x + on).min(x1);
        area.draw(&PathElement::new(
            vec![(x, y), (end, y)],
            color.stroke_width(width),
        ))
        .map_err(err)?;
        x = end + off;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, chart: &Chart) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let (w, _) = root.dim_in_pixel();
    let (plot, panel) = root.split_horizontally(w.saturating_sub(PANEL_WIDTH));
    let all = || {
        chart
            .curves
            .iter()
            .flat_map(|c| c.points.iter().copied())
            .chain(chart.front.iter().copied())
    };
    let (x0, x1) = decades(all().map(|p| p.0));
    let (y0, y1) = decades(all().map(|p| p.1.max(ERROR_FLOOR)));
    let mut ctx = ChartBuilder::on(&plot)
        .caption(&chart.title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(70)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(err)?;
    ctx.configure_mesh()
        .x_desc(&chart.x_label)
        .y_desc(&chart.y_label)
        .x_label_formatter(&|v| format!("{v:.0e}"))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(err)?;
    for c in &chart.curves {
        let color = PALETTE[c.color % PALETTE.len()];
        let pts: Vec<(f64, f64)> = c
            .points
            .iter()
            .map(|&(x, y)| (x, y.max(ERROR_FLOOR)))
            .collect();
        let style = color.stroke_width(2);
        match c.style {
            LineKind::Solid => ctx.draw_series(LineSeries::new(pts.clone(), style)),
            LineKind::Dashed => ctx.draw_series(DashedLineSeries::new(pts.clone(), 8, 5, style)),
            LineKind::Dotted => ctx.draw_series(DashedLineSeries::new(pts.clone(), 2, 4, style)),
            LineKind::Thick => ctx.draw_series(LineSeries::new(pts.clone(), color.stroke_width(4))),
            LineKind::LongDash => ctx.draw_series(DashedLineSeries::new(pts.clone(), 14, 4, style)),
        }
        .map_err(err)?;
        ctx.draw_series(pts.iter().map(|&p| Circle::new(p, 2, color.filled())))
            .map_err(err)?;
    }
    if !chart.front.is_empty() {
        ctx.draw_series(LineSeries::new(chart.front.clone(), BLACK.stroke_width(1)))
            .map_err(err)?;
        ctx.draw_series(
            chart
                .front
                .iter()
                .map(|&p| Circle::new(p, 4, BLACK.stroke_width(1))),
        )
        .map_err(err)?;
    }
    // Each note is a number beside its point (below and right of it: the curves run
    // from upper left to lower right, so the text sits off them); its text is in the panel.
    let number_font = ("sans-serif", 14).into_font().color(&BLACK);
    for (k, (x, y, _)) in chart.notes.iter().enumerate() {
        let at = ctx.backend_coord(&(*x, y.max(ERROR_FLOOR)));
        let label = format!("{}", k + 1);
        let (bx, by) = (at.0 + 6, at.1 + 4);
        let wide = 8 * label.len() as i32 + 6;
        plot.draw(&Rectangle::new(
            [(bx, by), (bx + wide, by + 17)],
            WHITE.filled(),
        ))
        .map_err(err)?;
        plot.draw(&Rectangle::new(
            [(bx, by), (bx + wide, by + 17)],
            BLACK.stroke_width(1),
        ))
        .map_err(err)?;
        plot.draw(&Text::new(label, (bx + 3, by + 1), number_font.clone()))
            .map_err(err)?;
    }

    // The panel: integrators, step policies, the front, then the notes.
    let heading = ("sans-serif", 14).into_font().color(&BLACK);
    let text = ("sans-serif", 12).into_font().color(&BLACK);
    let mut y = 50;
    let line = |area: &DrawingArea<DB, Shift>, s: &str, font: &TextStyle, y: &mut i32| {
        let r = area.draw(&Text::new(s.to_owned(), (40, *y - 6), font.clone()));
        *y += 18;
        r.map_err(err)
    };
    line(&panel, "integrator (colour)", &heading, &mut y)?;
    for (ci, name) in &chart.colors {
        let color = PALETTE[ci % PALETTE.len()];
        panel
            .draw(&Rectangle::new([(10, y - 10), (30, y - 2)], color.filled()))
            .map_err(err)?;
        line(&panel, name, &text, &mut y)?;
    }
    y += 8;
    line(&panel, "step policy (line)", &heading, &mut y)?;
    for (kind, name) in &chart.styles {
        sample_line(&panel, (8, 32, y - 6), *kind, RGBColor(60, 60, 60))?;
        line(&panel, name, &text, &mut y)?;
    }
    if !chart.front.is_empty() {
        sample_line(&panel, (8, 32, y - 6), LineKind::Solid, BLACK)?;
        panel
            .draw(&Circle::new((20, y - 6), 4, BLACK.stroke_width(1)))
            .map_err(err)?;
        line(&panel, "Pareto front", &text, &mut y)?;
    }
    if !chart.notes.is_empty() {
        y += 8;
        line(&panel, "cheapest per error decade", &heading, &mut y)?;
        for (k, (_, _, note)) in chart.notes.iter().enumerate() {
            // Wrapped at ~52 characters a line, continuation lines indented.
            let mut rest = note.trim();
            let mut first = true;
            while !rest.is_empty() {
                let cut = if rest.len() <= 52 {
                    rest.len()
                } else {
                    rest[..52].rfind(' ').unwrap_or(52)
                };
                let (head, tail) = rest.split_at(cut);
                let shown = if first {
                    format!("{}  {}", k + 1, head.trim())
                } else {
                    format!("    {}", head.trim())
                };
                panel
                    .draw(&Text::new(shown, (10, y - 6), text.clone()))
                    .map_err(err)?;
                y += 16;
                rest = tail.trim();
                first = false;
            }
        }
    }
    root.present().map_err(err)?;
    Ok(())
}

/// Chart size in pixels.
pub const SIZE: (u32, u32) = (1400, 760);

/// The chart as SVG text.
pub fn svg(chart: &Chart) -> anyhow::Result<String> {
    ensure_font()?;
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, SIZE).into_drawing_area();
        draw(root, chart)?;
    }
    Ok(out)
}

/// The chart as PNG bytes.
pub fn png(chart: &Chart) -> anyhow::Result<Vec<u8>> {
    ensure_font()?;
    let (w, h) = SIZE;
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
        draw(root, chart)?;
    }
    let img = image::RgbImage::from_raw(w, h, buf)
        .ok_or_else(|| anyhow::Error::msg("chart buffer has the wrong size"))?;
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )?;
    Ok(bytes)
}
