//! Error-against-cost charts (plotters): log-log, one curve per method (colour = integrator,
//! line = step policy), the Pareto front in black, and the method to use at each error
//! decade written on it. Drawn once for SVG and once for PNG.

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
    /// Notes drawn at (cost, error): the method named per decade.
    pub notes: Vec<(f64, f64, String)>,
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

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, chart: &Chart) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let all = || {
        chart
            .curves
            .iter()
            .flat_map(|c| c.points.iter().copied())
            .chain(chart.front.iter().copied())
    };
    let (x0, x1) = decades(all().map(|p| p.0));
    let (y0, y1) = decades(all().map(|p| p.1.max(ERROR_FLOOR)));
    let mut ctx = ChartBuilder::on(&root)
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
        let anno = match c.style {
            LineKind::Solid => ctx.draw_series(LineSeries::new(pts.clone(), style)),
            LineKind::Dashed => ctx.draw_series(DashedLineSeries::new(pts.clone(), 8, 5, style)),
            LineKind::Dotted => ctx.draw_series(DashedLineSeries::new(pts.clone(), 2, 4, style)),
            LineKind::Thick => ctx.draw_series(LineSeries::new(pts.clone(), color.stroke_width(4))),
        }
        .map_err(err)?;
        anno.label(&c.label).legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
        });
        ctx.draw_series(pts.iter().map(|&p| Circle::new(p, 2, color.filled())))
            .map_err(err)?;
    }
    if !chart.front.is_empty() {
        ctx.draw_series(LineSeries::new(chart.front.clone(), BLACK.stroke_width(1)))
            .map_err(err)?
            .label("Pareto front")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.stroke_width(1)));
        ctx.draw_series(
            chart
                .front
                .iter()
                .map(|&p| Circle::new(p, 4, BLACK.stroke_width(1))),
        )
        .map_err(err)?;
    }
    for (x, y, text) in &chart.notes {
        ctx.draw_series(std::iter::once(Text::new(
            text.clone(),
            (*x, y.max(ERROR_FLOOR)),
            ("sans-serif", 13).into_font().color(&BLACK),
        )))
        .map_err(err)?;
    }
    ctx.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 12))
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// Chart size in pixels.
pub const SIZE: (u32, u32) = (1100, 760);

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
