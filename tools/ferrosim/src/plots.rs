//! Plots of a simulation or a replay, each as PNG and SVG (plotters).

use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

use crate::simulate::Report;
use crate::tracking::Tracking;

/// Plots need a font and a machine may have none installed: DejaVu Sans is
/// compiled in.
fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

const SIZE: (u32, u32) = (1000, 560);
const COLOURS: [RGBColor; 4] = [RGBColor(31, 119, 180), RGBColor(214, 39, 40), RGBColor(44, 160, 44), RGBColor(255, 127, 14)];

/// One line of a chart.
pub struct Series<'a> {
    pub name: &'a str,
    pub points: Vec<(f64, f64)>,
}

/// At most `max` points, keeping each bucket's extreme (a plot of a
/// million samples shows the same peaks).
fn thin(points: &[(f64, f64)], max: usize) -> Vec<(f64, f64)> {
    if points.len() <= max {
        return points.to_vec();
    }
    let bucket = points.len().div_ceil(max);
    points.chunks(bucket).map(|c| *c.iter().max_by(|a, b| a.1.total_cmp(&b.1)).unwrap_or(&c[0])).collect()
}

/// At most `max` points keeping each bucket's lowest and highest, in time
/// order: for signed data (a tracking error), where [`thin`]'s maxima would
/// hide the negative peaks.
pub fn envelope(points: &[(f64, f64)], max: usize) -> Vec<(f64, f64)> {
    if points.len() <= max {
        return points.to_vec();
    }
    let bucket = points.len().div_ceil(max / 2).max(2);
    let mut out = Vec::with_capacity(max);
    for chunk in points.chunks(bucket) {
        let low = chunk.iter().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap_or(&chunk[0]);
        let high = chunk.iter().max_by(|a, b| a.1.total_cmp(&b.1)).unwrap_or(&chunk[0]);
        if low.0 <= high.0 {
            out.extend([*low, *high]);
        } else {
            out.extend([*high, *low]);
        }
    }
    out
}

fn bounds(series: &[Series]) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, 0.0f64, f64::MIN);
    for s in series {
        for &(x, y) in &s.points {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if x0 >= x1 {
        (x0, x1) = (0.0, 1.0);
    }
    if y0 >= y1 {
        y1 = y0 + 1.0;
    }
    (x0..x1, y0..y1 + (y1 - y0) * 0.05)
}

fn draw_lines<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let (xs, ys) = bounds(series);
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(xs, ys)
        .map_err(|e| e.to_string())?;
    chart.configure_mesh().x_desc(x_label).y_desc(y_label).draw().map_err(|e| e.to_string())?;
    for (i, s) in series.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        chart
            .draw_series(LineSeries::new(thin(&s.points, 4000), colour.stroke_width(1)))
            .map_err(|e| e.to_string())?
            .label(s.name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour));
    }
    if series.len() > 1 {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())
}

/// A line chart written as `<stem>.png` and `<stem>.svg`; the two paths.
pub fn line_chart(stem: &Path, title: &str, x_label: &str, y_label: &str, series: &[Series]) -> Result<[PathBuf; 2], String> {
    register_font();
    let png = stem.with_extension("png");
    let svg = stem.with_extension("svg");
    draw_lines(&BitMapBackend::new(&png, SIZE).into_drawing_area(), title, x_label, y_label, series)?;
    draw_lines(&SVGBackend::new(&svg, SIZE).into_drawing_area(), title, x_label, y_label, series)?;
    Ok([png, svg])
}

/// Blue (slow) to red (fast).
fn speed_colour(speed: f64, max: f64) -> RGBColor {
    let f = (speed / max.max(1e-9)).clamp(0.0, 1.0);
    RGBColor((255.0 * f) as u8, (80.0 * (1.0 - (2.0 * f - 1.0).abs())) as u8, (255.0 * (1.0 - f)) as u8)
}

fn draw_path<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, title: &str, path: &[(f64, f64, f64)]) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y, _) in path {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if path.is_empty() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    // Same scale on both axes.
    let span = (x1 - x0).max(y1 - y0).max(1.0) * 1.05;
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let max_speed = path.iter().map(|p| p.2).fold(0.0, f64::max);
    let mut chart = ChartBuilder::on(root)
        .caption(format!("{title} (blue: slow, red: {max_speed:.0} mm/s)"), ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(cx - span / 2.0..cx + span / 2.0, cy - span / 2.0..cy + span / 2.0)
        .map_err(|e| e.to_string())?;
    chart.configure_mesh().x_desc("X (mm)").y_desc("Y (mm)").draw().map_err(|e| e.to_string())?;
    chart
        .draw_series(path.windows(2).map(|w| {
            PathElement::new(vec![(w[0].0, w[0].1), (w[1].0, w[1].1)], speed_colour(w[1].2, max_speed).stroke_width(2))
        }))
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())
}

/// The XY path of one layer coloured by speed, as PNG and SVG.
pub fn path_chart(stem: &Path, title: &str, path: &[(f64, f64, f64)]) -> Result<[PathBuf; 2], String> {
    register_font();
    let png = stem.with_extension("png");
    let svg = stem.with_extension("svg");
    draw_path(&BitMapBackend::new(&png, (800, 800)).into_drawing_area(), title, path)?;
    draw_path(&SVGBackend::new(&svg, (800, 800)).into_drawing_area(), title, path)?;
    Ok([png, svg])
}

/// Every plot of a simulation into `dir`; `layer`: index into
/// [`Report::layers`] (default: the middle one). Returns the files.
pub fn simulation_plots(report: &Report, dir: &Path, layer: Option<usize>) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut files = Vec::new();
    files.extend(line_chart(
        &dir.join("speed"),
        "Tool speed along the path",
        "time (s)",
        "mm/s",
        &[Series { name: "speed", points: report.path_speed() }],
    )?);
    let names = report.machine.motor_names();
    let rates = report.step_rates();
    let series: Vec<Series> = rates.into_iter().enumerate().map(|(i, points)| Series { name: names[i], points }).collect();
    files.extend(line_chart(&dir.join("step_rates"), "Step rate per motor", "time (s)", "steps/s", &series)?);
    let thermal = &report.thermal;
    files.extend(line_chart(
        &dir.join("temperatures"),
        "Heaters",
        "time (s)",
        "°C",
        &[
            Series { name: "hot end", points: thermal.iter().map(|t| (t.time_s, t.hotend_c)).collect() },
            Series { name: "bed", points: thermal.iter().map(|t| (t.time_s, t.bed_c)).collect() },
        ],
    )?);
    files.extend(line_chart(
        &dir.join("heater_duty"),
        "Heater duty",
        "time (s)",
        "%",
        &[
            Series { name: "hot end", points: thermal.iter().map(|t| (t.time_s, t.hotend_duty * 100.0)).collect() },
            Series { name: "bed", points: thermal.iter().map(|t| (t.time_s, t.bed_duty * 100.0)).collect() },
        ],
    )?);
    let layers = report.layers();
    if !layers.is_empty() {
        let index = layer.unwrap_or(layers.len() / 2).min(layers.len() - 1);
        let z = layers[index];
        files.extend(path_chart(
            &dir.join("layer"),
            &format!("Layer {index} of {}, Z {z:.2} mm", layers.len()),
            &report.layer_path(z),
        )?);
    }
    Ok(files)
}

/// The closed-loop X and Y tracking error over time (`tracking_error.png`
/// and `.svg` in `dir`).
pub fn tracking_plots(tracking: &Tracking, dir: &Path) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let [x, y] = tracking.error_series();
    let title = format!(
        "Tracking error, reference − encoder ({}, {} Hz)",
        hal_sim::axis_plant::strategy_label(tracking.strategy),
        tracking.loop_hz
    );
    Ok(line_chart(
        &dir.join("tracking_error"),
        &title,
        "time (s)",
        "mm",
        &[Series { name: "X", points: envelope(&x, 4000) }, Series { name: "Y", points: envelope(&y, 4000) }],
    )?
    .to_vec())
}
