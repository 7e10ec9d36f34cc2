//! What the benches run in interleaved rounds share: the median of a round's figures, and
//! their settings read from the environment.

/// The median of `values` (the mean of the middle two for an even count).
pub fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// The count the environment variable `name` gives (`TALUS_ROUNDS`, `TALUS_REPLICA`), or
/// `default` where it is unset or not a count: `cargo bench` passes `--bench` (and any
/// filter), so the benches take their settings from the environment.
pub fn env_count(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}
