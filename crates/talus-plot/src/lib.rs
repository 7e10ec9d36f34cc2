//! SVG charts for the figures Talus puts in `docs/`: lines and markers on linear or
//! logarithmic axes, drawn with plotters and a font embedded in the binary (DejaVu Sans,
//! its licence in `fonts/`), so that no system library or font is needed.

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;

/// Colours of successive series (colour-blind-safe, Okabe–Ito).
const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(0, 0, 0),
];

static FONT: Once = Once::new();

fn register_font() {
    FONT.call_once(|| {
        // The bytes are a valid TrueType font shipped with the crate; failure would be a
        // packaging error, reported by the first chart's text drawing.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            include_bytes!("../fonts/DejaVuSans.ttf"),
        );
    });
}

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mark {
    /// A polyline through the points.
    Line,
    /// A circle at each point.
    Points,
    /// Both.
    LineAndPoints,
}

/// One named series of (x, y) points.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// Points, in drawing order.
    pub points: Vec<(f64, f64)>,
    /// How to draw it.
    pub mark: Mark,
}

impl Series {
    /// A series drawn as a line.
    pub fn line(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            mark: Mark::Line,
        }
    }

    /// A series drawn as markers.
    pub fn points(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            mark: Mark::Points,
        }
    }

    /// A series drawn as a line with markers.
    pub fn line_and_points(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            mark: Mark::LineAndPoints,
        }
    }
}

/// An axis: its label and scale.
#[derive(Clone, Debug, Default)]
pub struct Axis {
    /// Label, with the unit, e.g. "time step (s)".
    pub label: String,
    /// Logarithmic scale (non-positive values are left out).
    pub log: bool,
}

impl Axis {
    /// A linear axis.
    pub fn linear(label: impl Into<String>) -> Self {
        Self {
            label: label.into(),
            log: false,
        }
    }

    /// A logarithmic axis.
    pub fn log(label: impl Into<String>) -> Self {
        Self {
            label: label.into(),
            log: true,
        }
    }
}

/// A chart: title, axes, series.
#[derive(Clone, Debug)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// Horizontal axis.
    pub x: Axis,
    /// Vertical axis.
    pub y: Axis,
    /// The series, drawn in order with the palette's colours.
    pub series: Vec<Series>,
    /// Size in pixels.
    pub size: (u32, u32),
}

impl Chart {
    /// A 720 × 480 chart.
    pub fn new(title: impl Into<String>, x: Axis, y: Axis) -> Self {
        Self {
            title: title.into(),
            x,
            y,
            series: Vec::new(),
            size: (720, 480),
        }
    }

    /// Adds a series.
    pub fn with(mut self, series: Series) -> Self {
        self.series.push(series);
        self
    }
}

/// Why a chart could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// No point can be drawn (empty series, or nothing positive on a log axis).
    #[error("chart `{0}` has no point to draw")]
    Empty(String),
    /// The drawing or the file failed.
    #[error("cannot draw chart `{title}` to {path}: {message}")]
    Draw {
        /// Chart title.
        title: String,
        /// Output file.
        path: String,
        /// What plotters said.
        message: String,
    },
}

/// Range of finite values, left out non-positive ones on a log axis, padded a little.
fn range(values: impl Iterator<Item = f64>, log: bool) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return None;
    }
    Some(if log {
        if lo == hi {
            (lo / 2.0, hi * 2.0)
        } else {
            (lo / 1.3, hi * 1.3)
        }
    } else {
        let pad = if lo == hi {
            lo.abs().max(1.0) * 0.1
        } else {
            0.05 * (hi - lo)
        };
        (lo - pad, hi + pad)
    })
}

/// Writes the chart as an SVG file.
pub fn write_svg(chart: &Chart, path: &Path) -> Result<(), PlotError> {
    register_font();
    let fail = |message: String| PlotError::Draw {
        title: chart.title.clone(),
        path: path.display().to_string(),
        message,
    };
    let visible = |s: &Series| -> Vec<(f64, f64)> {
        s.points
            .iter()
            .copied()
            .filter(|(x, y)| {
                x.is_finite()
                    && y.is_finite()
                    && (!chart.x.log || *x > 0.0)
                    && (!chart.y.log || *y > 0.0)
            })
            .collect()
    };
    let all: Vec<(f64, f64)> = chart.series.iter().flat_map(visible).collect();
    let xr = range(all.iter().map(|p| p.0), chart.x.log);
    let yr = range(all.iter().map(|p| p.1), chart.y.log);
    let (Some(xr), Some(yr)) = (xr, yr) else {
        return Err(PlotError::Empty(chart.title.clone()));
    };
    let root = SVGBackend::new(path, chart.size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
    let result = match (chart.x.log, chart.y.log) {
        (false, false) => draw(&root, chart, xr.0..xr.1, yr.0..yr.1, &visible),
        (true, false) => draw(&root, chart, (xr.0..xr.1).log_scale(), yr.0..yr.1, &visible),
        (false, true) => draw(&root, chart, xr.0..xr.1, (yr.0..yr.1).log_scale(), &visible),
        (true, true) => draw(
            &root,
            chart,
            (xr.0..xr.1).log_scale(),
            (yr.0..yr.1).log_scale(),
            &visible,
        ),
    };
    result.map_err(fail)?;
    root.present().map_err(|e| fail(e.to_string()))
}

fn draw<X, Y>(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    chart: &Chart,
    x: X,
    y: Y,
    visible: &dyn Fn(&Series) -> Vec<(f64, f64)>,
) -> Result<(), String>
where
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let mut c = ChartBuilder::on(root)
        .caption(&chart.title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(x, y)
        .map_err(|e| e.to_string())?;
    c.configure_mesh()
        .x_desc(chart.x.label.as_str())
        .y_desc(chart.y.label.as_str())
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(|e| e.to_string())?;
    for (k, s) in chart.series.iter().enumerate() {
        let colour = PALETTE[k % PALETTE.len()];
        let points = visible(s);
        if matches!(s.mark, Mark::Line | Mark::LineAndPoints) {
            c.draw_series(LineSeries::new(
                points.iter().copied(),
                colour.stroke_width(2),
            ))
            .map_err(|e| e.to_string())?
            .label(s.name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
            });
        }
        if matches!(s.mark, Mark::Points | Mark::LineAndPoints) {
            let series = c
                .draw_series(points.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                .map_err(|e| e.to_string())?;
            if s.mark == Mark::Points {
                series
                    .label(s.name.as_str())
                    .legend(move |(x, y)| Circle::new((x + 9, y), 3, colour.filled()));
            }
        }
    }
    c.configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 13))
        .draw()
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_linear_and_log_charts_with_text() {
        let dir = std::env::temp_dir().join(format!("talus-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (xlog, ylog) in [(false, false), (true, true), (true, false), (false, true)] {
            let x = if xlog {
                Axis::log("x (1)")
            } else {
                Axis::linear("x (1)")
            };
            let y = if ylog {
                Axis::log("y (1)")
            } else {
                Axis::linear("y (1)")
            };
            let chart = Chart::new("a chart", x, y)
                .with(Series::line(
                    "x²",
                    (1..50).map(|i| (i as f64, (i * i) as f64)).collect(),
                ))
                .with(Series::points(
                    "x",
                    (1..50).map(|i| (i as f64, i as f64)).collect(),
                ));
            let path = dir.join(format!("c{xlog}{ylog}.svg"));
            write_svg(&chart, &path).unwrap();
            let svg = std::fs::read_to_string(&path).unwrap();
            assert!(svg.starts_with("<svg"));
            assert!(svg.contains("a chart") && svg.contains("x²"));
        }
        let empty = Chart::new("empty", Axis::log("x"), Axis::linear("y"))
            .with(Series::line("none", vec![(-1.0, 1.0)]));
        assert!(matches!(
            write_svg(&empty, &dir.join("e.svg")),
            Err(PlotError::Empty(_))
        ));
    }
}
