//! Reading grains from a LAMMPS data file (`atom_style sphere`), so that users migrating
//! from LAMMPS can start from their own states: the `Atoms` section (id type diameter
//! density x y z [image flags]) and, if present, `Velocities` (id vx vy vz wx wy wz).

use std::path::Path;

use glam::DVec3;

/// One atom of a data file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Atom {
    /// Atom id.
    pub id: u64,
    /// Atom type.
    pub atom_type: u32,
    /// Diameter.
    pub diameter: f64,
    /// Density.
    pub density: f64,
    /// Centre.
    pub position: DVec3,
    /// Velocity (zero without a `Velocities` section).
    pub velocity: DVec3,
    /// Angular velocity (zero without a `Velocities` section).
    pub angular_velocity: DVec3,
}

/// What is wrong with a data file, with the line (1-based) it was found on.
#[derive(Clone, Debug, PartialEq)]
pub struct DataError {
    /// Line of the file, 0 when the problem is the whole file.
    pub line: usize,
    /// What was expected.
    pub message: String,
}

fn err(line: usize, message: impl Into<String>) -> DataError {
    DataError {
        line,
        message: message.into(),
    }
}

/// Reads the atoms of a LAMMPS data file, in the order of the `Atoms` section.
pub fn read_data(path: &Path) -> Result<Vec<Atom>, DataError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| err(0, format!("a readable LAMMPS data file ({e})")))?;
    parse_data(&text)
}

/// The box lengths of a data file's header (`xlo xhi`, `ylo yhi`, `zlo zhi` lines); an
/// axis without its line is `None`.
pub fn box_lengths(path: &Path) -> Result<[Option<f64>; 3], DataError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| err(0, format!("a readable LAMMPS data file ({e})")))?;
    let mut out = [None; 3];
    for (k, line) in text.lines().enumerate() {
        let line = strip(line);
        if line == "Atoms" {
            break;
        }
        for (a, tag) in ["xlo xhi", "ylo yhi", "zlo zhi"].iter().enumerate() {
            if line.ends_with(tag) {
                let f: Vec<&str> = line.split_whitespace().collect();
                let lo: f64 = number(k + 1, &f, 0, "box bound")?;
                let hi: f64 = number(k + 1, &f, 1, "box bound")?;
                out[a] = Some(hi - lo);
            }
        }
    }
    Ok(out)
}

/// Parses the text of a LAMMPS data file.
pub fn parse_data(text: &str) -> Result<Vec<Atom>, DataError> {
    let lines: Vec<&str> = text.lines().collect();
    let mut declared: Option<usize> = None;
    let mut atoms: Vec<Atom> = Vec::new();
    let mut velocities: Vec<(u64, DVec3, DVec3, usize)> = Vec::new();
    // The first line is a title; the header runs until the first section keyword.
    let mut k = 1;
    while k < lines.len() {
        let line = strip(lines[k]);
        k += 1;
        if line.is_empty() {
            continue;
        }
        match line {
            "Atoms" | "Velocities" => {
                let section = line;
                let start = k;
                let rows = read_rows(&lines, &mut k);
                if section == "Atoms" {
                    for (n, fields) in rows {
                        atoms.push(parse_atom(n, &fields)?);
                    }
                } else {
                    for (n, fields) in rows {
                        velocities.push(parse_velocity(n, &fields)?);
                    }
                }
                let _ = start;
            }
            _ if line.ends_with("atoms") => {
                let count = line.split_whitespace().next().unwrap_or("");
                declared = Some(count.parse().map_err(|_| {
                    err(k, format!("an atom count before `atoms`, found `{count}`"))
                })?);
            }
            _ if line.starts_with(|c: char| c.is_ascii_alphabetic()) => {
                // Another section (Masses, Bonds, ...): skip its rows.
                read_rows(&lines, &mut k);
            }
            _ => {} // other header lines: box bounds, type counts
        }
    }
    let Some(declared) = declared else {
        return Err(err(0, "a header line `N atoms`"));
    };
    if atoms.len() != declared {
        return Err(err(
            0,
            format!(
                "{declared} rows in the Atoms section (the header says so), found {}",
                atoms.len()
            ),
        ));
    }
    if !velocities.is_empty() {
        let mut index: Vec<(u64, usize)> =
            atoms.iter().enumerate().map(|(i, a)| (a.id, i)).collect();
        index.sort_unstable();
        for (id, v, w, line) in velocities {
            let Ok(at) = index.binary_search_by_key(&id, |e| e.0) else {
                return Err(err(
                    line,
                    format!("a velocity for an atom of the Atoms section, found id {id}"),
                ));
            };
            let a = &mut atoms[index[at].1];
            a.velocity = v;
            a.angular_velocity = w;
        }
    }
    Ok(atoms)
}

/// A line without its `#` comment, trimmed.
fn strip(line: &str) -> &str {
    line.split('#').next().unwrap_or("").trim()
}

/// The rows of a section: after one blank line, until the next blank line following rows.
fn read_rows<'a>(lines: &[&'a str], k: &mut usize) -> Vec<(usize, Vec<&'a str>)> {
    let mut rows = Vec::new();
    while *k < lines.len() && strip(lines[*k]).is_empty() {
        *k += 1;
    }
    while *k < lines.len() {
        let line = strip(lines[*k]);
        if line.is_empty() {
            break;
        }
        rows.push((*k + 1, line.split_whitespace().collect()));
        *k += 1;
    }
    rows
}

fn number<T: std::str::FromStr>(
    line: usize,
    fields: &[&str],
    i: usize,
    what: &str,
) -> Result<T, DataError> {
    let s = fields
        .get(i)
        .ok_or_else(|| err(line, format!("a {what} in column {}", i + 1)))?;
    s.parse().map_err(|_| {
        err(
            line,
            format!("a number for the {what} in column {}, found `{s}`", i + 1),
        )
    })
}

fn parse_atom(line: usize, f: &[&str]) -> Result<Atom, DataError> {
    if !(f.len() == 7 || f.len() == 10) {
        return Err(err(
            line,
            format!(
                "an atom_style sphere row `id type diameter density x y z [ix iy iz]` (7 or 10 columns), found {}",
                f.len()
            ),
        ));
    }
    let atom = Atom {
        id: number(line, f, 0, "atom id")?,
        atom_type: number(line, f, 1, "atom type")?,
        diameter: number(line, f, 2, "diameter")?,
        density: number(line, f, 3, "density")?,
        position: DVec3::new(
            number(line, f, 4, "x")?,
            number(line, f, 5, "y")?,
            number(line, f, 6, "z")?,
        ),
        velocity: DVec3::ZERO,
        angular_velocity: DVec3::ZERO,
    };
    if !(atom.diameter > 0.0 && atom.diameter.is_finite()) {
        return Err(err(
            line,
            format!("a positive diameter, found {}", atom.diameter),
        ));
    }
    if !(atom.density > 0.0 && atom.density.is_finite()) {
        return Err(err(
            line,
            format!("a positive density, found {}", atom.density),
        ));
    }
    if !atom.position.is_finite() {
        return Err(err(line, "finite coordinates"));
    }
    Ok(atom)
}

fn parse_velocity(line: usize, f: &[&str]) -> Result<(u64, DVec3, DVec3, usize), DataError> {
    if f.len() != 7 {
        return Err(err(
            line,
            format!(
                "a Velocities row `id vx vy vz wx wy wz` (7 columns), found {}",
                f.len()
            ),
        ));
    }
    let id = number(line, f, 0, "atom id")?;
    let mut c = [0.0; 6];
    for (i, v) in c.iter_mut().enumerate() {
        *v = number(line, f, i + 1, "velocity component")?;
    }
    let v = DVec3::new(c[0], c[1], c[2]);
    let w = DVec3::new(c[3], c[4], c[5]);
    if !(v.is_finite() && w.is_finite()) {
        return Err(err(line, "finite velocities"));
    }
    Ok((id, v, w, line))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = "title line\n\n2 atoms\n\n2 atom types\n\n0 40 xlo xhi\n\nAtoms\n\n1 1 1 1 19.4 6.4 14.5 33 0 0\n2 2 1.5 2 1 2 3 0 0 0\n\nVelocities\n\n2 1 2 3 4 5 6\n1 0.5 0 0 0 0 0.25\n";

    #[test]
    fn reads_atoms_and_velocities_by_id() {
        let atoms = parse_data(SMALL).unwrap();
        assert_eq!(atoms.len(), 2);
        assert_eq!(atoms[1].atom_type, 2);
        assert_eq!(atoms[1].diameter, 1.5);
        assert_eq!(atoms[1].position, DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(atoms[1].angular_velocity, DVec3::new(4.0, 5.0, 6.0));
        assert_eq!(atoms[0].velocity, DVec3::new(0.5, 0.0, 0.0));
    }

    #[test]
    fn malformed_files_name_the_line() {
        let bad = SMALL.replace("1 1 1 1 19.4", "1 1 x 1 19.4");
        let e = parse_data(&bad).unwrap_err();
        assert_eq!(e.line, 11, "{e:?}");
        assert!(e.message.contains("diameter"), "{e:?}");
        let short = SMALL.replace("2 atoms", "3 atoms");
        assert!(parse_data(&short).unwrap_err().message.contains("3 rows"));
        let stray = SMALL.replace("1 0.5 0 0 0 0 0.25", "7 0.5 0 0 0 0 0.25");
        assert_eq!(parse_data(&stray).unwrap_err().line, 17);
        assert!(parse_data("").is_err());
    }
}
