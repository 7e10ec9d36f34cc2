//! Bad scenes fail before the run with the file, line, column and field, never a panic.

use talus::scene::{SceneError, parse};

const GOOD: &str = r#"Scene(
    name: "ok",
    steps: 10,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.5))],
    grains: [List(material: "glass", grains: [(position: (0.0, 0.0, 0.0), radius: 0.01)])],
)"#;

fn error_of(text: &str) -> SceneError {
    let outcome = std::panic::catch_unwind(|| {
        parse("bad.ron", text).and_then(|s| s.build(&talus::registry()).map(|_| ()))
    });
    match outcome {
        Ok(Err(e)) => e,
        Ok(Ok(())) => panic!("scene was accepted:\n{text}"),
        Err(_) => panic!("scene handling panicked:\n{text}"),
    }
}

fn line_col_of(text: &str, needle: &str) -> (usize, usize) {
    let at = text.find(needle).expect("needle in text");
    let line = text[..at].matches('\n').count() + 1;
    let col = at - text[..at].rfind('\n').map(|i| i + 1).unwrap_or(0) + 1;
    (line, col)
}

#[test]
fn the_good_scene_is_accepted() {
    parse("good.ron", GOOD)
        .unwrap()
        .build(&talus::registry())
        .unwrap();
}

#[test]
fn misspelt_field() {
    let text = GOOD.replace("density:", "densty:");
    let e = error_of(&text);
    assert_eq!(e.line, line_col_of(&text, "densty").0, "{e}");
    assert!(e.column > 0);
    assert!(e.field.contains("densty"), "{e}");
    assert!(e.expected.contains("density"), "{e}");
}

#[test]
fn negative_radius() {
    let text = GOOD.replace("radius: 0.01", "radius: -0.01");
    let e = error_of(&text);
    assert_eq!((e.line, e.column), line_col_of(&text, "-0.01"), "{e}");
    assert_eq!(e.field, "grains[0].grains[0].radius", "{e}");
    assert!(e.expected.contains("positive"), "{e}");
}

#[test]
fn missing_required_field() {
    let text = GOOD.replace("density: 2500.0,", "");
    let e = error_of(&text);
    assert!(e.field.ends_with("density"), "{e}");
    assert_eq!(e.line, line_col_of(&text, "(name: \"glass\"").0, "{e}");
    assert!(e.column > 0);
}

#[test]
fn restitution_out_of_range() {
    let text = GOOD.replace("restitution: 0.5", "restitution: 1.5");
    let e = error_of(&text);
    assert_eq!((e.line, e.column), line_col_of(&text, "1.5"), "{e}");
    assert_eq!(e.field, "materials[0].contact.restitution", "{e}");
    assert!(e.expected.contains("(0, 1]"), "{e}");
}

#[test]
fn not_ron_at_all() {
    let text = "{ \"name\": \"json?\", ";
    let e = error_of(text);
    assert!(e.line >= 1 && e.column >= 1, "{e}");
    assert!(e.to_string().starts_with("bad.ron:"), "{e}");
}

#[test]
fn unknown_law_and_overlapping_grains_and_unstable_step() {
    let e = error_of(&GOOD.replace(
        "law: \"linear_spring\", stiffness",
        "law: \"hooke\", stiffness",
    ));
    assert_eq!(e.field, "materials[0].contact.law", "{e}");
    let text = GOOD.replace(
        "(position: (0.0, 0.0, 0.0), radius: 0.01)",
        "(position: (0.0, 0.0, 0.0), radius: 0.01), (position: (0.015, 0.0, 0.0), radius: 0.01)",
    );
    let e = error_of(&text);
    assert_eq!(e.field, "grains[0]", "{e}");
    assert!(e.expected.contains("overlap"), "{e}");
    let e = error_of(&GOOD.replace("steps: 10,", "steps: 10, time_step: 1.0,"));
    assert_eq!(e.field, "time_step", "{e}");
    assert!(e.expected.contains("stability"), "{e}");
}

#[test]
fn rotation_off_with_a_law_that_torques_grains() {
    let text = GOOD
        .replace("restitution: 0.5))", "restitution: 0.5, friction: 0.4))")
        .replace("steps: 10,", "steps: 10,\n    rotation: false,");
    let e = error_of(&text);
    assert!(e.field.ends_with(".law"), "{e}");
    assert!(e.expected.contains("rotation"), "{e}");
    assert!(e.line > 0, "{e}");
}

#[test]
fn unknown_rolling_part() {
    let text = GOOD.replace(
        "restitution: 0.5))",
        "restitution: 0.5, rolling: \"sticky\"))",
    );
    let e = error_of(&text);
    assert_eq!(e.field, "materials[0].contact.rolling", "{e}");
    assert!(e.expected.contains("sticky"), "{e}");
    assert_eq!(e.line, line_col_of(&text, "rolling").0, "{e}");
}

#[test]
fn the_same_material_pair_twice() {
    let text = GOOD.replacen(
        "grains: [",
        "pairs: [(materials: (\"glass\", \"glass\"), contact: (law: \"linear_spring\", stiffness: 1e4, restitution: 0.5)),\n        (materials: (\"glass\", \"glass\"), contact: (law: \"linear_spring\", stiffness: 2e4, restitution: 0.5))],\n    grains: [",
        1,
    );
    let e = error_of(&text);
    assert_eq!(e.field, "pairs[1].materials", "{e}");
    assert!(e.expected.contains("pairs[0]"), "{e}");
}

#[test]
fn two_walls_with_one_name() {
    let text = GOOD.replacen(
        "grains: [",
        "walls: [Plane(name: \"floor\", point: (0.0, 0.0, -1.0), normal: (0.0, 0.0, 1.0), material: \"glass\"),\n        Plane(name: \"floor\", point: (0.0, 0.0, 1.0), normal: (0.0, 0.0, -1.0), material: \"glass\")],\n    grains: [",
        1,
    );
    let e = error_of(&text);
    assert_eq!(e.field, "walls[1].name", "{e}");
    assert_eq!(
        e.line,
        line_col_of(&text, "Plane(name: \"floor\", point: (0.0, 0.0, 1.0)").0,
        "{e}"
    );
}

#[test]
fn strain_rate_wall_needs_a_facing_wall_by_name() {
    let with_walls = |walls: &str| {
        GOOD.replace(
            "    grains:",
            &format!("    walls: [{walls}],\n    grains:"),
        )
    };
    let floor = r#"Plane(name: "floor", point: (0.0, 0.0, -0.1), normal: (0.0, 0.0, 1.0), material: "glass")"#;
    // An unknown opposite wall.
    let text = with_walls(&format!(
        r#"{floor}, Plane(name: "lid", point: (0.0, 0.0, 0.1), normal: (0.0, 0.0, -1.0), material: "glass", strain_rate: (rate: 1.0, opposite: "flor"))"#
    ));
    let e = error_of(&text);
    assert_eq!(e.field, "walls[1].strain_rate.opposite", "{e}");
    assert!(e.expected.contains("`floor`"), "{e}");
    assert_eq!(e.line, line_col_of(&text, "opposite: \"flor\"").0, "{e}");
    // A wall that does not face it.
    let text = with_walls(&format!(
        r#"{floor}, Plane(name: "side", point: (0.1, 0.0, 0.0), normal: (-1.0, 0.0, 0.0), material: "glass", strain_rate: (rate: 1.0, opposite: "floor"))"#
    ));
    let e = error_of(&text);
    assert_eq!(e.field, "walls[1].strain_rate.opposite", "{e}");
    assert!(e.expected.contains("facing"), "{e}");
    // Both a servo and a strain rate.
    let text = with_walls(&format!(
        r#"{floor}, Plane(name: "lid", point: (0.0, 0.0, 0.1), normal: (0.0, 0.0, -1.0), material: "glass", servo: (pressure: 1.0, area: 1.0, gain: 1.0), strain_rate: (rate: 1.0, opposite: "floor"))"#
    ));
    let e = error_of(&text);
    assert_eq!(e.field, "walls[1].strain_rate", "{e}");
    // Two walls driven against each other at different rates.
    let text = with_walls(
        r#"Plane(name: "floor", point: (0.0, 0.0, -0.1), normal: (0.0, 0.0, 1.0), material: "glass", strain_rate: (rate: 2.0, opposite: "lid")), Plane(name: "lid", point: (0.0, 0.0, 0.1), normal: (0.0, 0.0, -1.0), material: "glass", strain_rate: (rate: 1.0, opposite: "floor"))"#,
    );
    let e = error_of(&text);
    assert!(e.field.ends_with("strain_rate.rate"), "{e}");
    assert!(e.expected.contains("same rate"), "{e}");
}

#[test]
fn grains_overlapping_through_a_periodic_seam() {
    let text = r#"Scene(
    name: "seam",
    steps: 10,
    periodic: (x: (0.0, 0.1)),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.5))],
    grains: [List(material: "glass", grains: [
        (position: (0.005, 0.0, 0.0), radius: 0.01),
        (position: (0.05, 0.0, 0.0), radius: 0.01),
        (position: (0.095, 0.0, 0.0), radius: 0.01),
    ])],
)"#;
    let e = error_of(text);
    assert!(e.field.starts_with("grains[0]"), "{e}");
    assert!(e.expected.contains("across the periodic boundary"), "{e}");
    assert!(e.to_string().contains("through the seam"), "{e}");
    // The same grains a little further apart are accepted: 0.02 apart through the seam.
    let clear = text.replace("0.095", "0.085");
    parse("clear.ron", &clear)
        .unwrap()
        .build(&talus::registry())
        .unwrap();
}

#[test]
fn sorting_the_grains_every_zero_steps() {
    let text = GOOD.replace("steps: 10,", "steps: 10,\n    sort_grains_every: 0,");
    let e = error_of(&text);
    assert_eq!(
        (e.line, e.column),
        line_col_of(&text, "0,\n    plugins"),
        "{e}"
    );
    assert_eq!(e.field, "sort_grains_every", "{e}");
    assert!(e.expected.contains("positive number of steps"), "{e}");
}
