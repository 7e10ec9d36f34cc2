//! The `talus` command line: `talus run`, `talus check` and `talus accuracy`, the run loop with
//! progress, the JSON run report, and the last good state kept for blow-ups.
//!
//! The binary in the workspace root supplies the registry of contact laws; this crate
//! never names a law.

pub mod accuracy;
pub mod alloc;
pub mod report;
pub mod run;

pub use report::{Report, ReportSample};
pub use run::{RunError, RunOptions, RunSummary, check_scene, run_scene};

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use talus_contact::LawRegistry;

/// Talus: discrete-element simulation of granular matter.
#[derive(Parser, Debug)]
#[command(name = "talus", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Sub-commands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run a scene, writing DIR/recording.rrd and DIR/report.json.
    Run {
        /// The scene file (RON).
        scene: PathBuf,
        /// Output folder. Default: out/<scene name>/.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads. Default: all cores.
        #[arg(long)]
        threads: Option<usize>,
        /// No progress bar and no summary.
        #[arg(long)]
        quiet: bool,
        /// Continue the run saved in this state file (a `state.ron` or
        /// `last_good_state.ron` this scene wrote) up to the scene's end.
        #[arg(long, value_name = "STATE")]
        resume: Option<PathBuf>,
        /// Write the final state to DIR/state.ron (also when the scene does not ask).
        #[arg(long)]
        save_state: bool,
    },
    /// Validate a scene and print its plan without running it.
    Check {
        /// The scene file (RON).
        scene: PathBuf,
    },
    /// Run an accuracy study: one scene under several settings, error against wall
    /// clock, written to DIR/study.md, study.csv and study.svg.
    Accuracy {
        /// The study file (RON): `Study(scene: ..., quantity: ..., settings: [...])`.
        study: PathBuf,
        /// Output folder. Default: out/<study file name>/.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

/// Fixes glibc's threshold above which an allocation gets its own mapping, returned to
/// the system when freed. By default glibc raises that threshold to the size of any such
/// block freed (up to 32 MiB): after a scene's build frees its large buffers, the
/// snapshot's and the tables' arrays land in the heap instead, where the holes their
/// growth leaves are never returned. Fixing it at glibc's initial 128 KiB brings the peak
/// resident memory of the 512,000-grain chute down by 4 % (docs/performance-log.md); the run
/// allocates nothing that large per step, so it costs no page faults.
fn fix_mmap_threshold() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets a parameter of the allocator; it is called before any
    // other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 128 * 1024);
    }
}

/// Runs the command line with the given contact laws.
pub fn main_with(registry: LawRegistry) -> ExitCode {
    fix_mmap_threshold();
    let cli = Cli::parse();
    match cli.command {
        Command::Check { scene } => match check_scene(&scene, &registry) {
            Ok(text) => {
                print!("{text}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
        Command::Accuracy { study, out } => {
            let out = out.unwrap_or_else(|| {
                PathBuf::from("out").join(study.file_stem().unwrap_or_default())
            });
            // On a pool worker, like `run` (see there).
            let study_result = match rayon::ThreadPoolBuilder::new().build() {
                Ok(pool) => pool.install(|| accuracy::run_study(&study, &registry, &out)),
                Err(e) => {
                    eprintln!("error: cannot start the thread pool: {e}");
                    return ExitCode::from(2);
                }
            };
            match study_result {
                Ok(result) => {
                    for r in &result.rows {
                        println!(
                            "{:<50} dt {:.3e} s  value {:.8e}  error {:.3e}  {:.3} s",
                            r.setting.label(),
                            r.dt,
                            r.value,
                            r.error,
                            r.seconds
                        );
                    }
                    match result.fastest_within_tolerance {
                        Some(k) => println!(
                            "fastest within {:.1e}: {}",
                            result.tolerance,
                            result.rows[k].setting.label()
                        ),
                        None => println!("no setting reaches {:.1e}", result.tolerance),
                    }
                    for f in &result.files {
                        println!("wrote {}", f.display());
                    }
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::from(2)
                }
            }
        }
        Command::Run {
            scene,
            out,
            threads,
            quiet,
            resume,
            save_state,
        } => {
            // The run itself goes on a worker of the pool: a parallel loop started from a
            // worker runs its first part at once on that thread, instead of waking a pool
            // thread and putting the caller to sleep at every loop (which cost a context
            // switch per parallel loop, several per step).
            let pool = match rayon::ThreadPoolBuilder::new()
                .num_threads(threads.unwrap_or(0))
                .build()
            {
                Ok(pool) => pool,
                Err(e) => {
                    eprintln!("error: cannot start the thread pool: {e}");
                    return ExitCode::from(2);
                }
            };
            let options = RunOptions {
                out,
                quiet,
                progress: !quiet,
                resume,
                save_state,
            };
            match pool.install(|| run_scene(&scene, &registry, &options)) {
                Ok(summary) => {
                    if !quiet {
                        println!("{}", summary.describe());
                    }
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::from(match e {
                        RunError::Scene(_) => 2,
                        _ => 1,
                    })
                }
            }
        }
    }
}
