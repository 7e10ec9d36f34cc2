//! Maps field paths of a RON text (`materials[0].contact.stiffness`) to line and
//! column, so that errors found after parsing point at the right place.
//!
//! A structural scan only: it follows brackets, field names, strings and comments,
//! and records where each value starts. It never judges validity (ron does that).

/// A bracketed group: its path, and the (line, column) of its opener and of its closer.
type Group = (String, (usize, usize), (usize, usize));

/// Positions of the values of a RON text, by field path.
#[derive(Clone, Debug, Default)]
pub struct Locator {
    entries: Vec<(String, usize, usize)>,
    /// Bracketed groups: path, start (line, column), end (line, column) of the closer.
    groups: Vec<Group>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Tok {
    Open(char),
    Close(char),
    Comma,
    Colon,
    Ident,
    Scalar,
}

struct Token {
    kind: Tok,
    text: String,
    line: usize,
    col: usize,
}

fn tokenize(src: &str) -> Vec<Token> {
    let chars: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut line, mut col) = (0usize, 1usize, 1usize);
    let advance = |i: &mut usize, line: &mut usize, col: &mut usize, c: char| {
        *i += 1;
        if c == '\n' {
            *line += 1;
            *col = 1;
        } else {
            *col += 1;
        }
    };
    while i < chars.len() {
        let c = chars[i];
        let (l0, c0) = (line, col);
        if c.is_whitespace() {
            advance(&mut i, &mut line, &mut col, c);
        } else if c == '/' && chars.get(i + 1) == Some(&'/') {
            while i < chars.len() && chars[i] != '\n' {
                {
                    let ch = chars[i];
                    advance(&mut i, &mut line, &mut col, ch);
                }
            }
        } else if c == '/' && chars.get(i + 1) == Some(&'*') {
            let mut depth = 0;
            while i < chars.len() {
                if chars[i] == '/' && chars.get(i + 1) == Some(&'*') {
                    depth += 1;
                    advance(&mut i, &mut line, &mut col, '/');
                } else if chars[i] == '*' && chars.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    advance(&mut i, &mut line, &mut col, '*');
                    if depth == 0 {
                        advance(&mut i, &mut line, &mut col, '/');
                        break;
                    }
                }
                {
                    let ch = chars[i];
                    advance(&mut i, &mut line, &mut col, ch);
                }
            }
        } else if c == '"' || c == '\'' {
            let quote = c;
            let mut text = String::new();
            advance(&mut i, &mut line, &mut col, c);
            while i < chars.len() && chars[i] != quote {
                if chars[i] == '\\' && i + 1 < chars.len() {
                    advance(&mut i, &mut line, &mut col, '\\');
                }
                text.push(chars[i]);
                {
                    let ch = chars[i];
                    advance(&mut i, &mut line, &mut col, ch);
                }
            }
            if i < chars.len() {
                advance(&mut i, &mut line, &mut col, quote);
            }
            out.push(Token {
                kind: Tok::Scalar,
                text,
                line: l0,
                col: c0,
            });
        } else if "([{".contains(c) {
            advance(&mut i, &mut line, &mut col, c);
            out.push(Token {
                kind: Tok::Open(c),
                text: c.to_string(),
                line: l0,
                col: c0,
            });
        } else if ")]}".contains(c) {
            advance(&mut i, &mut line, &mut col, c);
            out.push(Token {
                kind: Tok::Close(c),
                text: c.to_string(),
                line: l0,
                col: c0,
            });
        } else if c == ',' || c == ':' {
            advance(&mut i, &mut line, &mut col, c);
            out.push(Token {
                kind: if c == ',' { Tok::Comma } else { Tok::Colon },
                text: c.to_string(),
                line: l0,
                col: c0,
            });
        } else {
            let mut text = String::new();
            // A bare word runs to whitespace, punctuation or a comment's opener.
            let ends_word = |i: usize| {
                chars[i].is_whitespace()
                    || "()[]{},:\"'".contains(chars[i])
                    || (chars[i] == '/' && matches!(chars.get(i + 1), Some('/') | Some('*')))
            };
            while i < chars.len() && !ends_word(i) {
                text.push(chars[i]);
                {
                    let ch = chars[i];
                    advance(&mut i, &mut line, &mut col, ch);
                }
            }
            let is_ident = text
                .chars()
                .next()
                .is_some_and(|c| c.is_alphabetic() || c == '_');
            out.push(Token {
                kind: if is_ident { Tok::Ident } else { Tok::Scalar },
                text,
                line: l0,
                col: c0,
            });
        }
    }
    out
}

struct Scanner {
    toks: Vec<Token>,
    at: usize,
    entries: Vec<(String, usize, usize)>,
    groups: Vec<Group>,
}

impl Scanner {
    fn peek(&self, k: usize) -> Option<&Token> {
        self.toks.get(self.at + k)
    }

    fn value(&mut self, path: &str) {
        let Some(t) = self.peek(0) else { return };
        let (kind, line, col) = (t.kind, t.line, t.col);
        self.entries.push((path.to_string(), line, col));
        match kind {
            Tok::Ident => {
                self.at += 1;
                if matches!(self.peek(0).map(|t| t.kind), Some(Tok::Open('('))) {
                    self.at += 1;
                    self.group(path, ')');
                }
            }
            Tok::Open(c) => {
                self.at += 1;
                let close = match c {
                    '(' => ')',
                    '[' => ']',
                    _ => '}',
                };
                self.group(path, close);
            }
            _ => self.at += 1,
        }
    }

    /// Contents of a bracketed group up to and including `close`.
    fn group(&mut self, path: &str, close: char) {
        let mut index = 0usize;
        let start = self
            .at
            .checked_sub(1)
            .and_then(|i| self.toks.get(i))
            .map(|t| (t.line, t.col))
            .unwrap_or((1, 1));
        loop {
            let Some(t) = self.peek(0) else { return };
            match t.kind {
                Tok::Close(_) => {
                    self.groups.push((path.to_string(), start, (t.line, t.col)));
                    self.at += 1;
                    return;
                }
                Tok::Comma => {
                    self.at += 1;
                    continue;
                }
                _ => {}
            }
            let named = close != ']'
                && matches!(t.kind, Tok::Ident | Tok::Scalar)
                && matches!(self.peek(1).map(|t| t.kind), Some(Tok::Colon));
            if named {
                let key = t.text.clone();
                let (line, col) = (t.line, t.col);
                self.at += 2;
                let child = if path.is_empty() {
                    key
                } else {
                    format!("{path}.{key}")
                };
                // A field whose value is missing still has a position: its key.
                self.entries.push((child.clone(), line, col));
                self.value(&child);
            } else {
                let child = format!("{path}[{index}]");
                self.value(&child);
                index += 1;
            }
        }
    }
}

impl Locator {
    /// Scans a RON text.
    pub fn new(src: &str) -> Self {
        let mut s = Scanner {
            toks: tokenize(src),
            at: 0,
            entries: Vec::new(),
            groups: Vec::new(),
        };
        // A top-level struct may carry a name: `Scene( ... )`.
        s.value("");
        while s.at < s.toks.len() {
            s.at += 1;
        }
        let mut entries = s.entries;
        // Keep the value position (the later entry) of each path.
        entries.reverse();
        let mut seen = std::collections::HashSet::new();
        entries.retain(|(p, ..)| seen.insert(p.clone()));
        entries.reverse();
        Self {
            entries,
            groups: s.groups,
        }
    }

    /// The innermost bracketed value containing a position: its path and where it starts.
    pub fn group_at(&self, line: usize, col: usize) -> Option<(String, (usize, usize))> {
        self.groups
            .iter()
            .filter(|(_, start, end)| *start <= (line, col) && (line, col) <= *end)
            .max_by_key(|(_, start, _)| *start)
            .map(|(p, start, _)| (p.clone(), *start))
    }

    /// Line and column of a field's value; for a path that is not in the text (a
    /// missing field), the position of its nearest enclosing field.
    pub fn position(&self, path: &str) -> (usize, usize) {
        let mut p = path.to_string();
        loop {
            if let Some((_, l, c)) = self.entries.iter().find(|(q, ..)| *q == p) {
                return (*l, *c);
            }
            match p.rfind(['.', '[']) {
                Some(cut) => p.truncate(cut),
                None => return (1, 1),
            }
        }
    }

    /// The innermost field whose value starts at or before a position.
    pub fn field_at(&self, line: usize, col: usize) -> Option<String> {
        self.entries
            .iter()
            .filter(|(_, l, c)| (*l, *c) <= (line, col))
            .max_by_key(|(p, l, c)| (*l, *c, p.len()))
            .map(|(p, ..)| p.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_nested_fields_and_list_items() {
        let src = "Scene(\n  name: \"x\", // c\n  materials: [\n    (name: \"a\", contact: (law: \"l\", stiffness: 1e5)),\n  ],\n)";
        let l = Locator::new(src);
        assert_eq!(l.position("name"), (2, 9));
        assert_eq!(l.position("materials[0].contact.stiffness"), (4, 48));
        assert_eq!(l.position("materials[0].density"), (4, 5));
        assert_eq!(
            l.field_at(4, 56).as_deref(),
            Some("materials[0].contact.stiffness")
        );
    }
}
