//! Draws the figures of `docs/laws/hdem.md` (`docs/laws/figures/hdem-*.svg`) from the
//! data the ignored test `write_rocking_figure_data` of `tests/hdem.rs` writes to
//! `target/hdem-figures/`. Run from the workspace root:
//!
//! ```text
//! cargo test --release --test physics -- --ignored hdem::write_rocking_figure_data
//! cargo run --release -p talus-hdem --example hdem_figures
//! ```

use std::path::{Path, PathBuf};

use talus_plot::{Axis, Chart, Series, write_svg};

/// Columns of a CSV file with a header line, by name.
struct Table {
    header: Vec<String>,
    rows: Vec<Vec<f64>>,
}

impl Table {
    fn read(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("{}: {e} (run the ignored data test first)", path.display()))?;
        let mut lines = text.lines();
        let header = lines
            .next()
            .ok_or_else(|| format!("{}: empty", path.display()))?
            .split(',')
            .map(str::to_string)
            .collect();
        let rows = lines
            .map(|l| {
                l.split(',')
                    .map(|x| x.parse().unwrap_or(f64::NAN))
                    .collect()
            })
            .collect();
        Ok(Self { header, rows })
    }

    /// (x, y) points of two columns, every `stride`-th row.
    fn points(&self, x: &str, y: &str, stride: usize) -> Vec<(f64, f64)> {
        let column = |name: &str| self.header.iter().position(|h| h == name);
        let (Some(i), Some(j)) = (column(x), column(y)) else {
            return Vec::new();
        };
        self.rows
            .iter()
            .step_by(stride.max(1))
            .map(|r| (r[i], r[j]))
            .filter(|(a, b)| a.is_finite() && b.is_finite())
            .collect()
    }
}

fn main() -> Result<(), String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let data = root.join("target/hdem-figures");
    let out = root.join("docs/laws/figures");
    std::fs::create_dir_all(&out).map_err(|e| e.to_string())?;
    let series = |kind: &str, model: &str| Table::read(&data.join(format!("{kind}-{model}.csv")));
    let (conventional, hdem) = (
        series("rocking", "conventional")?,
        series("rocking", "hdem")?,
    );
    let (conventional_cycles, hdem_cycles) =
        (series("cycles", "conventional")?, series("cycles", "hdem")?);
    let save = |chart: Chart, name: &str| -> Result<PathBuf, String> {
        let path = out.join(name);
        write_svg(&chart, &path).map_err(|e| e.to_string())?;
        println!("wrote {}", path.display());
        Ok(path)
    };
    save(
        Chart::new(
            "Free-rocking disk: rolling angle about the rest position",
            Axis::linear("time (s)"),
            Axis::linear("θ − θ_rest (rad)"),
        )
        .with(Series::line(
            "conventional (elastic–plastic, ζ = 0.05)",
            conventional.points("time", "angle", 2),
        ))
        .with(Series::line(
            "HDEM (β = 0.844, ζ = 0.02)",
            hdem.points("time", "angle", 2),
        )),
        "hdem-rocking-angle.svg",
    )?;
    save(
        Chart::new(
            "Kinetic-energy envelope (largest kinetic energy of each half cycle)",
            Axis::linear("time (s)"),
            Axis::log("kinetic energy (J)"),
        )
        .with(Series::line_and_points(
            "conventional",
            conventional_cycles.points("time", "peak_kinetic", 1),
        ))
        .with(Series::line_and_points(
            "HDEM",
            hdem_cycles.points("time", "peak_kinetic", 1),
        )),
        "hdem-kinetic-envelope.svg",
    )?;
    save(
        Chart::new(
            "Rocking frequency from successive zero crossings of the spin",
            Axis::linear("time (s)"),
            Axis::linear("π / half period (rad/s)"),
        )
        .with(Series::points(
            "conventional",
            conventional_cycles.points("time", "frequency", 1),
        ))
        .with(Series::points(
            "HDEM",
            hdem_cycles.points("time", "frequency", 1),
        )),
        "hdem-frequency.svg",
    )?;
    let share: Vec<(f64, f64)> = {
        let hyst = hdem_cycles.points("time", "hysteresis", 1);
        let damp = hdem_cycles.points("time", "damping", 1);
        hyst.iter()
            .zip(&damp)
            .filter(|(h, d)| h.1 + d.1 > 0.0)
            .map(|(h, d)| (h.0, h.1 / (h.1 + d.1)))
            .collect()
    };
    save(
        Chart::new(
            "HDEM: hysteresis share of the rocking dissipation, per half cycle",
            Axis::linear("time (s)"),
            Axis::linear("hysteresis / (hysteresis + dashpot)"),
        )
        .with(Series::line_and_points("HDEM", share)),
        "hdem-dissipation-share.svg",
    )?;
    save(
        Chart::new(
            "HDEM: cumulative dissipation by channel",
            Axis::linear("time (s)"),
            Axis::linear("dissipated energy (J)"),
        )
        .with(Series::line(
            "rolling_hysteresis",
            hdem.points("time", "hysteresis", 10),
        ))
        .with(Series::line(
            "rolling_damping",
            hdem.points("time", "damping", 10),
        ))
        .with(Series::line(
            "rolling_slip",
            hdem.points("time", "slip", 10),
        ))
        .with(Series::line(
            "conventional: rolling_damping",
            conventional.points("time", "damping", 10),
        )),
        "hdem-dissipation.svg",
    )?;
    Ok(())
}
