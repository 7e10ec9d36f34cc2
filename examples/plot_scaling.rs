//! Draws the strong-scaling curve of the chute benchmark from the table that
//! `benches/scaling.py` writes: the speed-up over 1 thread against the thread count, one
//! line per packing size, with the ideal (speed-up equal to the thread count) beside them.
//!
//! `cargo run --release --example plot_scaling -- scaling.tsv docs/figures/strong-scaling.svg`
//!
//! Each round's runs are divided by that round's 1-thread run of the same size, and the
//! median of those ratios is drawn, so that a slow stretch of the machine, which touches
//! a whole round, cancels out (`docs/performance.md`, "Strong scaling").

use std::collections::BTreeMap;
use std::path::Path;
use std::process::ExitCode;

#[path = "../benches/support/rounds.rs"]
#[allow(dead_code)]
mod rounds;
use rounds::median;

/// One run of the table: its round, grain count, thread count and rate.
struct Run {
    round: u32,
    grains: u64,
    threads: u32,
    rate: f64,
}

/// Reads the runs of a `benches/scaling.py` table, naming the line and column of
/// anything it cannot read.
fn read_runs(path: &Path) -> Result<Vec<Run>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut lines = text.lines().enumerate();
    let (_, header) = lines
        .next()
        .ok_or_else(|| format!("{}: empty file", path.display()))?;
    let columns: Vec<&str> = header.split('\t').collect();
    let column = |name: &str| {
        columns
            .iter()
            .position(|c| *c == name)
            .ok_or_else(|| format!("{}:1: no column `{name}`", path.display()))
    };
    let (round, grains, threads, rate) = (
        column("round")?,
        column("grains")?,
        column("threads")?,
        column("grain_steps_per_second")?,
    );
    let mut runs = Vec::new();
    for (number, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split('\t').collect();
        let field = |index: usize, name: &str| -> Result<f64, String> {
            fields
                .get(index)
                .and_then(|f| f.parse::<f64>().ok())
                .ok_or_else(|| {
                    format!(
                        "{}:{}: column `{name}`: expected a number",
                        path.display(),
                        number + 1
                    )
                })
        };
        runs.push(Run {
            round: field(round, "round")? as u32,
            grains: field(grains, "grains")? as u64,
            threads: field(threads, "threads")? as u32,
            rate: field(rate, "grain_steps_per_second")?,
        });
    }
    Ok(runs)
}

/// Speed-up over 1 thread by grain count and thread count: the median over the rounds of
/// each round's ratio.
fn speed_ups(runs: &[Run]) -> BTreeMap<u64, Vec<(f64, f64)>> {
    let one_thread: BTreeMap<(u32, u64), f64> = runs
        .iter()
        .filter(|r| r.threads == 1)
        .map(|r| ((r.round, r.grains), r.rate))
        .collect();
    let mut ratios: BTreeMap<(u64, u32), Vec<f64>> = BTreeMap::new();
    for r in runs {
        if let Some(base) = one_thread.get(&(r.round, r.grains)) {
            ratios
                .entry((r.grains, r.threads))
                .or_default()
                .push(r.rate / base);
        }
    }
    let mut curves: BTreeMap<u64, Vec<(f64, f64)>> = BTreeMap::new();
    for ((grains, threads), values) in ratios {
        curves
            .entry(grains)
            .or_default()
            .push((f64::from(threads), median(values)));
    }
    curves
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [table, svg] = args.as_slice() else {
        eprintln!("usage: plot_scaling SCALING.tsv OUT.svg");
        return ExitCode::FAILURE;
    };
    let runs = match read_runs(Path::new(table)) {
        Ok(runs) => runs,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let curves = speed_ups(&runs);
    let most_threads = runs.iter().map(|r| r.threads).max().unwrap_or(1);
    let mut chart = talus_plot::Chart::new(
        "Chute benchmark: strong scaling (medians of per-round ratios)",
        talus_plot::Axis::linear("threads"),
        talus_plot::Axis::linear("speed-up over 1 thread"),
    );
    chart = chart.with(talus_plot::Series::line(
        "ideal",
        vec![
            (1.0, 1.0),
            (f64::from(most_threads), f64::from(most_threads)),
        ],
    ));
    for (grains, points) in curves {
        for &(threads, speed_up) in &points {
            println!("{grains} grains, {threads} threads: {speed_up:.2}x");
        }
        chart = chart.with(talus_plot::Series::line_and_points(
            format!("{grains} grains"),
            points,
        ));
    }
    match talus_plot::write_svg(&chart, Path::new(svg)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
