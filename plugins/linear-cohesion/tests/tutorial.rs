//! Keeps `docs/writing-a-contact-law.md` in sync with the code it teaches: every Rust
//! block of the tutorial, and every other block that opens with an excerpt marker, must
//! appear verbatim in the file its marker names.
//!
//! A marked block opens with `// excerpt: PATH` (Rust, RON) or `# excerpt: PATH` (TOML),
//! PATH relative to the workspace root; the rest of the block is the excerpt.

use std::path::{Path, PathBuf};

/// The workspace root: two levels above this crate.
fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// One fenced block of the tutorial.
struct Block {
    /// The word after the opening fence (`rust`, `toml`, ...).
    language: String,
    /// Line of the opening fence, 1-based.
    line: usize,
    /// The lines between the fences.
    lines: Vec<String>,
}

fn fenced_blocks(text: &str) -> Vec<Block> {
    let mut blocks = Vec::new();
    let mut open: Option<Block> = None;
    for (k, line) in text.lines().enumerate() {
        match (&mut open, line.strip_prefix("```")) {
            (None, Some(language)) => {
                open = Some(Block {
                    language: language.trim().to_string(),
                    line: k + 1,
                    lines: Vec::new(),
                })
            }
            (Some(_), Some(_)) => blocks.extend(open.take()),
            (Some(block), None) => block.lines.push(line.to_string()),
            (None, None) => {}
        }
    }
    assert!(open.is_none(), "the tutorial ends inside a fenced block");
    blocks
}

/// The file a block's first line names, if it is an excerpt marker.
fn excerpt_source(block: &Block) -> Option<&str> {
    let first = block.lines.first()?.trim();
    first
        .strip_prefix("// excerpt:")
        .or_else(|| first.strip_prefix("# excerpt:"))
        .map(str::trim)
}

#[test]
fn every_tutorial_excerpt_is_verbatim_in_the_file_it_names() {
    let root = workspace_root();
    let tutorial = root.join("docs/writing-a-contact-law.md");
    let text = std::fs::read_to_string(&tutorial)
        .unwrap_or_else(|e| panic!("{}: {e}", tutorial.display()));
    let blocks = fenced_blocks(&text);
    let mut checked = 0;
    let mut from_this_crate = 0;
    for block in &blocks {
        let Some(source) = excerpt_source(block) else {
            assert_ne!(
                block.language, "rust",
                "tutorial line {}: a Rust block without `// excerpt: PATH`; all its Rust is real code",
                block.line
            );
            continue;
        };
        let path = root.join(source);
        let code = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("tutorial line {}: {}: {e}", block.line, path.display()));
        let excerpt = block.lines[1..].join("\n");
        assert!(
            !excerpt.trim().is_empty(),
            "tutorial line {}: an empty excerpt",
            block.line
        );
        assert!(
            code.contains(&excerpt),
            "tutorial line {}: this excerpt is no longer in {source}; copy it again from there:\n{excerpt}",
            block.line
        );
        checked += 1;
        from_this_crate += usize::from(source.starts_with("plugins/linear-cohesion/"));
    }
    // A parser that found nothing would pass vacuously.
    assert!(checked >= 10, "only {checked} excerpts found");
    assert!(
        from_this_crate >= 8,
        "only {from_this_crate} excerpts of this crate"
    );
}

#[test]
fn files_the_tutorial_lists_exist() {
    let root = workspace_root();
    for file in [
        "plugins/linear-cohesion/Cargo.toml",
        "plugins/linear-cohesion/src/cohesion.rs",
        "plugins/linear-cohesion/src/lib.rs",
        "plugins/linear-cohesion/src/tests.rs",
        "tests/linear_cohesion.rs",
        "scenes/cohesive-pile.ron",
        "plugins/linear-spring/src/lib.rs",
    ] {
        assert!(root.join(file).is_file(), "{file} is missing");
    }
}
