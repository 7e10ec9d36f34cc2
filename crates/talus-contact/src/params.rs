//! Declared law parameters: names, units, ranges, defaults and mixing rules, so that a
//! scene can be validated against a law without the core knowing the law.

use std::fmt;

/// How the values of two unlike materials combine into the value for their pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MixRule {
    /// 2ab/(a + b): two equal springs in a row feel like one of them.
    Harmonic,
    /// √(ab).
    Geometric,
    /// (a + b)/2.
    Arithmetic,
    /// min(a, b).
    Min,
    /// max(a, b).
    Max,
}

impl MixRule {
    /// Combines two values.
    pub fn mix(self, a: f64, b: f64) -> f64 {
        match self {
            MixRule::Harmonic => {
                if a + b == 0.0 {
                    0.0
                } else {
                    2.0 * a * b / (a + b)
                }
            }
            MixRule::Geometric => (a * b).sqrt(),
            MixRule::Arithmetic => 0.5 * (a + b),
            MixRule::Min => a.min(b),
            MixRule::Max => a.max(b),
        }
    }

    /// Name used in documentation.
    pub fn describe(self) -> &'static str {
        match self {
            MixRule::Harmonic => "harmonic mean 2ab/(a+b)",
            MixRule::Geometric => "geometric mean √(ab)",
            MixRule::Arithmetic => "arithmetic mean (a+b)/2",
            MixRule::Min => "minimum",
            MixRule::Max => "maximum",
        }
    }
}

/// Allowed values of a parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamRange {
    /// Lower bound.
    pub min: f64,
    /// Whether the lower bound itself is allowed.
    pub min_inclusive: bool,
    /// Upper bound.
    pub max: f64,
    /// Whether the upper bound itself is allowed.
    pub max_inclusive: bool,
}

impl ParamRange {
    /// (0, ∞).
    pub const POSITIVE: Self = Self {
        min: 0.0,
        min_inclusive: false,
        max: f64::INFINITY,
        max_inclusive: false,
    };
    /// [0, ∞).
    pub const NON_NEGATIVE: Self = Self {
        min: 0.0,
        min_inclusive: true,
        max: f64::INFINITY,
        max_inclusive: false,
    };
    /// (0, 1].
    pub const UNIT_OPEN_CLOSED: Self = Self {
        min: 0.0,
        min_inclusive: false,
        max: 1.0,
        max_inclusive: true,
    };

    /// Whether `x` is allowed.
    pub fn contains(&self, x: f64) -> bool {
        let lo = if self.min_inclusive {
            x >= self.min
        } else {
            x > self.min
        };
        let hi = if self.max_inclusive {
            x <= self.max
        } else {
            x < self.max
        };
        x.is_finite() && lo && hi
    }
}

impl fmt::Display for ParamRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let lo = if self.min_inclusive { '[' } else { '(' };
        let hi = if self.max_inclusive { ']' } else { ')' };
        let max = if self.max.is_infinite() {
            "∞".to_string()
        } else {
            format!("{}", self.max)
        };
        write!(f, "a number in {lo}{}, {max}{hi}", self.min)
    }
}

/// One parameter a law reads from a scene.
#[derive(Clone, Copy, Debug)]
pub struct ParamSpec {
    /// Field name in the scene file.
    pub name: &'static str,
    /// SI unit.
    pub unit: &'static str,
    /// What it means.
    pub doc: &'static str,
    /// Allowed values.
    pub range: ParamRange,
    /// Value when absent; `None` means optional with no default (the law decides).
    pub default: Option<f64>,
    /// Mixing rule for unlike materials.
    pub mix: MixRule,
}

/// Parameter values by name, in declaration order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamValues(pub Vec<(String, f64)>);

impl ParamValues {
    /// The value of a parameter, if set.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, v)| *v)
    }

    /// Sets or replaces a value.
    pub fn set(&mut self, name: &str, value: f64) {
        match self.0.iter_mut().find(|(n, _)| n == name) {
            Some(entry) => entry.1 = value,
            None => self.0.push((name.to_string(), value)),
        }
    }

    /// Mixes two materials' values by each parameter's rule. A parameter set on only
    /// one side is taken from that side.
    pub fn mix(specs: &[ParamSpec], a: &ParamValues, b: &ParamValues) -> ParamValues {
        let mut out = ParamValues::default();
        for spec in specs {
            match (a.get(spec.name), b.get(spec.name)) {
                (Some(x), Some(y)) => out.set(spec.name, spec.mix.mix(x, y)),
                (Some(x), None) | (None, Some(x)) => out.set(spec.name, x),
                (None, None) => {}
            }
        }
        out
    }
}

/// A parameter problem, naming the field and what was expected.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamError {
    /// The offending field (a parameter name), or empty for the set as a whole.
    pub field: String,
    /// What was expected.
    pub expected: String,
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.field.is_empty() {
            write!(f, "{}", self.expected)
        } else {
            write!(f, "field `{}`: expected {}", self.field, self.expected)
        }
    }
}

impl std::error::Error for ParamError {}

/// Checks names and ranges of a parameter set against its specs and fills defaults.
pub fn check_params(specs: &[ParamSpec], values: &ParamValues) -> Result<ParamValues, ParamError> {
    for (name, value) in &values.0 {
        let Some(spec) = specs.iter().find(|s| s.name == name) else {
            let known: Vec<&str> = specs.iter().map(|s| s.name).collect();
            return Err(ParamError {
                field: name.clone(),
                expected: format!("one of the law's parameters: {}", known.join(", ")),
            });
        };
        if !spec.range.contains(*value) {
            return Err(ParamError {
                field: name.clone(),
                expected: format!("{} ({}), got {}", spec.range, spec.unit, value),
            });
        }
    }
    let mut out = values.clone();
    for spec in specs {
        if out.get(spec.name).is_none()
            && let Some(d) = spec.default
        {
            out.set(spec.name, d);
        }
    }
    Ok(out)
}
