//! The workspace-level tests, one module per file of this folder, built as one test binary:
//! each binary links the whole dependency tree (bevy_ecs, rerun with arrow) and
//! instantiates the simulation's generic code anew: thirty binaries took CI about four minutes
//! to compile and link on two cores, one takes under one. Run one file's tests with
//! `cargo test --release --test physics chute::` (the module name, then `::`).

mod common;

/// A file of this folder that no `mod` line names would never be compiled or run (the
/// binary is declared by hand in `Cargo.toml`, with `autotests = false`).
#[test]
fn every_test_file_is_a_module_of_the_binary() {
    let folder = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    let this = std::fs::read_to_string(folder.join("physics.rs")).expect("tests/physics.rs");
    let mut missing = Vec::new();
    for entry in std::fs::read_dir(&folder).expect("the tests folder") {
        let path = entry.expect("a folder entry").path();
        let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else {
            continue;
        };
        let is_rust_file = path.extension().is_some_and(|e| e == "rs");
        if is_rust_file && stem != "physics" && !this.contains(&format!("\nmod {stem};\n")) {
            missing.push(stem.to_owned());
        }
    }
    assert!(
        missing.is_empty(),
        "tests/physics.rs has no `mod` line for {missing:?}"
    );
}

mod accuracy_study;
mod binary_collision;
mod chute;
mod coarse_graining;
mod contact_history_reorder;
mod contact_table_sort;
mod deferred_kick;
mod determinism;
mod energy_conservation;
mod hard_cases;
mod hdem;
mod hertz_mindlin;
mod jiang_liu;
mod jiang_liu_cohesion;
mod lane_forms;
mod lees_edwards;
mod lees_edwards_stress;
mod linear_cohesion;
mod long_run;
mod neighbour_rebuild;
mod packing;
mod periodic;
mod pour_energy_balance;
mod recording;
mod reference_chute;
mod region_stages;
mod rest;
mod rolling_friction;
mod rolling_resistance;
mod save_load;
mod scene_errors;
mod servo;
mod stress_sampling;
