//! A small parser of the protobuf text format, as used by Brax v1 system configs.
//!
//! The result is a schema-free tree ([`Message`] of [`Field`]s) in which every field keeps
//! its line and column, so that the typed conversion ([`super::config`]) can name the exact
//! place of a wrong value. Supported syntax:
//!
//! - messages `name { ... }`, `name: { ... }` and `name < ... >`;
//! - scalar fields `name: value` where value is a number (`1`, `-0.5`, `1.8e-17`, `.5`,
//!   `1.0f`, `0x1F`, `-inf`, `nan`), a string (`"..."` or `'...'`, C escapes, adjacent
//!   strings concatenated) or an identifier (`true`, `false`, enum names);
//! - lists `name: [v1, v2]` and `name: [{...}, {...}]`, read as repeated fields;
//! - optional `,` or `;` after a field, comments from `#` to the end of the line.
//!
//! Repeated fields are simply several fields with the same name. Any malformed input gives a
//! [`BraxError::Syntax`] naming the source, line, column and what was expected; the parser
//! never panics and bounds its nesting depth.

use super::error::{BraxError, Location};

/// Deepest nesting of messages accepted (Brax configs use 3); deeper input is an error
/// rather than a stack overflow.
pub const MAX_DEPTH: usize = 64;

/// A message: an ordered list of fields (repeated fields appear several times).
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// 1-based line of the opening brace (1 for the top-level message).
    pub line: usize,
    /// 1-based column of the opening brace (1 for the top-level message).
    pub column: usize,
    /// The fields in the order written.
    pub fields: Vec<Field>,
}

/// One `name: value` or `name { ... }` entry.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// The field name.
    pub name: String,
    /// 1-based line of the field name.
    pub line: usize,
    /// 1-based column of the field name.
    pub column: usize,
    /// The value.
    pub value: Value,
}

/// The value of a field.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A number, with the text it was written as (for error messages).
    Number {
        /// The value (integers are exact up to 2^53).
        value: f64,
        /// The text as written, sign included.
        text: String,
    },
    /// A quoted string, escapes resolved.
    String(String),
    /// A bare identifier such as `true`, `false` or an enum name.
    Identifier(String),
    /// A nested message.
    Message(Message),
}

impl Value {
    /// A short rendering of the value for error messages (messages are shown as `{...}`).
    pub fn describe(&self) -> String {
        match self {
            Value::Number { text, .. } => text.clone(),
            Value::String(s) => format!("{s:?}"),
            Value::Identifier(s) => s.clone(),
            Value::Message(_) => "{...}".to_string(),
        }
    }
}

impl Message {
    /// All fields with the given name, in order.
    pub fn fields_named<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a Field> + 'a {
        self.fields.iter().filter(move |f| f.name == name)
    }
}

/// Parses `text` as a protobuf text-format message. `source` names the text in errors
/// (a file path or a built-in name).
pub fn parse(text: &str, source: &str) -> Result<Message, BraxError> {
    let tokens = Lexer::new(text, source).tokenize()?;
    let mut parser = Parser { tokens, pos: 0, source };
    let fields = parser.fields(None, 0)?;
    Ok(Message { line: 1, column: 1, fields })
}

/// A lexical token.
#[derive(Clone, Debug, PartialEq)]
enum Tok {
    /// A name: letters, digits, `_`, `.` (not starting with a digit).
    Ident(String),
    /// Unsigned numeric literal text.
    Number(String),
    /// A string literal, escapes resolved.
    Str(String),
    /// One of `{ } < > [ ] : , ; -`.
    Punct(char),
    /// End of input.
    Eof,
}

impl Tok {
    fn describe(&self) -> String {
        match self {
            Tok::Ident(s) => format!("`{s}`"),
            Tok::Number(s) => format!("number `{s}`"),
            Tok::Str(s) => format!("string {s:?}"),
            Tok::Punct(c) => format!("`{c}`"),
            Tok::Eof => "end of file".to_string(),
        }
    }
}

/// A token and where it starts.
#[derive(Clone, Debug)]
struct Spanned {
    tok: Tok,
    line: usize,
    column: usize,
}

/// Splits the text into tokens, skipping white space and comments.
struct Lexer<'a> {
    chars: Vec<char>,
    pos: usize,
    line: usize,
    column: usize,
    source: &'a str,
}

impl<'a> Lexer<'a> {
    fn new(text: &str, source: &'a str) -> Self {
        Lexer { chars: text.chars().collect(), pos: 0, line: 1, column: 1, source }
    }

    fn peek(&self) -> Option<char> {
        self.chars.get(self.pos).copied()
    }

    fn bump(&mut self) -> Option<char> {
        let c = self.chars.get(self.pos).copied()?;
        self.pos += 1;
        if c == '\n' {
            self.line += 1;
            self.column = 1;
        } else {
            self.column += 1;
        }
        Some(c)
    }

    fn error(&self, line: usize, column: usize, message: String) -> BraxError {
        BraxError::Syntax { location: Location { source: self.source.to_string(), line, column }, message }
    }

    fn tokenize(mut self) -> Result<Vec<Spanned>, BraxError> {
        let mut out = Vec::new();
        loop {
            // Skip white space and comments.
            while let Some(c) = self.peek() {
                if c.is_whitespace() {
                    self.bump();
                } else if c == '#' {
                    while let Some(c) = self.bump() {
                        if c == '\n' {
                            break;
                        }
                    }
                } else {
                    break;
                }
            }
            let (line, column) = (self.line, self.column);
            let Some(c) = self.peek() else {
                out.push(Spanned { tok: Tok::Eof, line, column });
                return Ok(out);
            };
            let tok = if "{}<>[]:,;-".contains(c) {
                self.bump();
                Tok::Punct(c)
            } else if c.is_ascii_digit()
                || (c == '.' && self.chars.get(self.pos + 1).is_some_and(|d| d.is_ascii_digit()))
            {
                Tok::Number(self.number())
            } else if c.is_alphabetic() || c == '_' {
                let mut s = String::new();
                while let Some(c) = self.peek() {
                    if c.is_alphanumeric() || c == '_' || c == '.' {
                        s.push(c);
                        self.bump();
                    } else {
                        break;
                    }
                }
                Tok::Ident(s)
            } else if c == '"' || c == '\'' {
                Tok::Str(self.string(line, column)?)
            } else {
                return Err(self.error(
                    line,
                    column,
                    format!("unexpected character {c:?}: expected a field name, a value or one of {{ }} < > [ ] : , ;"),
                ));
            };
            out.push(Spanned { tok, line, column });
        }
    }

    /// Reads the text of a numeric literal (validated later by the parser).
    fn number(&mut self) -> String {
        let mut s = String::new();
        while let Some(c) = self.peek() {
            let exponent_sign =
                (c == '+' || c == '-') && s.ends_with(['e', 'E']) && !s.starts_with("0x") && !s.starts_with("0X");
            if c.is_alphanumeric() || c == '.' || c == '_' || exponent_sign {
                s.push(c);
                self.bump();
            } else {
                break;
            }
        }
        s
    }

    /// Reads a quoted string starting at the current quote character.
    fn string(&mut self, line: usize, column: usize) -> Result<String, BraxError> {
        let quote = self.bump().unwrap_or('"');
        let mut s = String::new();
        loop {
            let (el, ec) = (self.line, self.column);
            match self.bump() {
                None | Some('\n') => {
                    return Err(self.error(
                        line,
                        column,
                        format!("unterminated string: expected a closing {quote} on the same line"),
                    ));
                }
                Some(c) if c == quote => return Ok(s),
                Some('\\') => {
                    let escaped = match self.bump() {
                        Some('n') => '\n',
                        Some('t') => '\t',
                        Some('r') => '\r',
                        Some('a') => '\u{7}',
                        Some('b') => '\u{8}',
                        Some('f') => '\u{c}',
                        Some('v') => '\u{b}',
                        Some(c @ ('\\' | '\'' | '"' | '?')) => c,
                        Some(d @ '0'..='7') => {
                            let mut code = d.to_digit(8).unwrap_or(0);
                            for _ in 0..2 {
                                match self.peek().and_then(|c| c.to_digit(8)) {
                                    Some(v) => {
                                        code = code * 8 + v;
                                        self.bump();
                                    }
                                    None => break,
                                }
                            }
                            char::from_u32(code).unwrap_or('\u{fffd}')
                        }
                        Some('x') => {
                            let mut code = 0u32;
                            let mut digits = 0;
                            while digits < 2 {
                                match self.peek().and_then(|c| c.to_digit(16)) {
                                    Some(v) => {
                                        code = code * 16 + v;
                                        self.bump();
                                        digits += 1;
                                    }
                                    None => break,
                                }
                            }
                            if digits == 0 {
                                return Err(self.error(
                                    el,
                                    ec,
                                    "invalid escape `\\x`: expected hexadecimal digits".into(),
                                ));
                            }
                            char::from_u32(code).unwrap_or('\u{fffd}')
                        }
                        other => {
                            let shown = other.map_or("end of file".to_string(), |c| format!("{c:?}"));
                            return Err(self.error(
                                el,
                                ec,
                                format!("invalid escape `\\` followed by {shown}: expected one of n t r a b f v \\ ' \" ? x or an octal digit"),
                            ));
                        }
                    };
                    s.push(escaped);
                }
                Some(c) => s.push(c),
            }
        }
    }
}

/// Recursive-descent parser over the token list.
struct Parser<'a> {
    tokens: Vec<Spanned>,
    pos: usize,
    source: &'a str,
}

impl Parser<'_> {
    fn peek(&self) -> &Spanned {
        // The token list always ends with Eof and `pos` never passes it.
        &self.tokens[self.pos.min(self.tokens.len() - 1)]
    }

    fn next(&mut self) -> Spanned {
        let t = self.peek().clone();
        if t.tok != Tok::Eof {
            self.pos += 1;
        }
        t
    }

    fn error_at(&self, t: &Spanned, message: String) -> BraxError {
        BraxError::Syntax {
            location: Location { source: self.source.to_string(), line: t.line, column: t.column },
            message,
        }
    }

    /// Parses fields until `close` (or end of file when `close` is None).
    /// `open` is the token that opened the enclosing message, for error messages.
    fn fields(&mut self, close: Option<(char, &Spanned, &str)>, depth: usize) -> Result<Vec<Field>, BraxError> {
        let mut fields = Vec::new();
        loop {
            let t = self.next();
            match (&t.tok, close) {
                (Tok::Eof, None) => return Ok(fields),
                (Tok::Punct(c), Some((want, _, _))) if *c == want => return Ok(fields),
                (Tok::Eof, Some((want, open, name))) => {
                    return Err(self.error_at(
                        &t,
                        format!(
                            "unexpected end of file: expected `{want}` to close `{name}` opened at line {}, column {}",
                            open.line, open.column
                        ),
                    ));
                }
                (Tok::Ident(name), _) => {
                    let name = name.clone();
                    self.field_value(&t, &name, depth, &mut fields)?;
                    // Optional separator.
                    if matches!(self.peek().tok, Tok::Punct(',') | Tok::Punct(';')) {
                        self.next();
                    }
                }
                (other, _) => {
                    let expected = match close {
                        Some((want, _, _)) => format!("a field name or `{want}`"),
                        None => "a field name".to_string(),
                    };
                    return Err(self.error_at(&t, format!("expected {expected}, found {}", other.describe())));
                }
            }
        }
    }

    /// Parses what follows a field name and appends the field(s) to `out`.
    fn field_value(
        &mut self,
        name_tok: &Spanned,
        name: &str,
        depth: usize,
        out: &mut Vec<Field>,
    ) -> Result<(), BraxError> {
        let make = |value: Value| Field { name: name.to_string(), line: name_tok.line, column: name_tok.column, value };
        let t = self.next();
        match &t.tok {
            Tok::Punct('{') | Tok::Punct('<') => {
                let m = self.message(&t, name, depth)?;
                out.push(make(Value::Message(m)));
            }
            Tok::Punct(':') => {
                let v = self.next();
                match v.tok {
                    Tok::Punct('{') | Tok::Punct('<') => {
                        let m = self.message(&v, name, depth)?;
                        out.push(make(Value::Message(m)));
                    }
                    Tok::Punct('[') => self.list(&v, name, depth, &make, out)?,
                    _ => {
                        let value = self.scalar(v, name)?;
                        out.push(make(value));
                    }
                }
            }
            other => {
                return Err(self.error_at(
                    &t,
                    format!("expected `:` or `{{` after field name `{name}`, found {}", other.describe()),
                ));
            }
        }
        Ok(())
    }

    /// Parses the body of a message whose opening token `open` was just read.
    fn message(&mut self, open: &Spanned, name: &str, depth: usize) -> Result<Message, BraxError> {
        if depth + 1 > MAX_DEPTH {
            return Err(self.error_at(open, format!("messages nested deeper than {MAX_DEPTH} levels")));
        }
        let close = if open.tok == Tok::Punct('<') { '>' } else { '}' };
        let fields = self.fields(Some((close, open, name)), depth + 1)?;
        Ok(Message { line: open.line, column: open.column, fields })
    }

    /// Parses `[a, b, ...]` after the `[` token `open`; each element becomes one field.
    fn list(
        &mut self,
        open: &Spanned,
        name: &str,
        depth: usize,
        make: &dyn Fn(Value) -> Field,
        out: &mut Vec<Field>,
    ) -> Result<(), BraxError> {
        if self.peek().tok == Tok::Punct(']') {
            self.next();
            return Ok(());
        }
        loop {
            let v = self.next();
            let value = match v.tok {
                Tok::Punct('{') | Tok::Punct('<') => Value::Message(self.message(&v, name, depth)?),
                Tok::Eof => {
                    return Err(self.error_at(
                        &v,
                        format!(
                            "unexpected end of file: expected `]` to close the list `{name}` opened at line {}, column {}",
                            open.line, open.column
                        ),
                    ));
                }
                _ => self.scalar(v, name)?,
            };
            out.push(make(value));
            let sep = self.next();
            match &sep.tok {
                Tok::Punct(',') => continue,
                Tok::Punct(']') => return Ok(()),
                other => {
                    return Err(self.error_at(
                        &sep,
                        format!("expected `,` or `]` in the list `{name}`, found {}", other.describe()),
                    ));
                }
            }
        }
    }

    /// Parses a scalar value whose first token `t` was just read.
    fn scalar(&mut self, t: Spanned, name: &str) -> Result<Value, BraxError> {
        match t.tok {
            Tok::Number(ref text) => self.number(&t, text, false),
            Tok::Punct('-') => {
                let n = self.next();
                match n.tok {
                    Tok::Number(ref text) => self.number(&n, text, true),
                    Tok::Ident(ref id) if is_special_float(id) => self.number(&n, id, true),
                    ref other => Err(self.error_at(
                        &n,
                        format!("expected a number after `-` in field `{name}`, found {}", other.describe()),
                    )),
                }
            }
            Tok::Ident(ref id) if is_special_float(id) => self.number(&t, id, false),
            Tok::Ident(ref id) => Ok(Value::Identifier(id.clone())),
            Tok::Str(ref first) => {
                // Adjacent string literals are concatenated.
                let mut s = first.clone();
                while let Tok::Str(more) = &self.peek().tok {
                    s.push_str(more);
                    self.next();
                }
                Ok(Value::String(s))
            }
            ref other => Err(self.error_at(
                &t,
                format!(
                    "expected a value (number, string, identifier or `{{`) for field `{name}`, found {}",
                    other.describe()
                ),
            )),
        }
    }

    /// Converts numeric literal text to a [`Value::Number`].
    fn number(&self, t: &Spanned, text: &str, negative: bool) -> Result<Value, BraxError> {
        let lower = text.to_ascii_lowercase();
        let magnitude = if let Some(hex) = lower.strip_prefix("0x") {
            u64::from_str_radix(hex, 16).ok().map(|v| v as f64)
        } else if is_special_float(&lower) {
            Some(if lower.starts_with("inf") { f64::INFINITY } else { f64::NAN })
        } else {
            let body = lower.strip_suffix('f').unwrap_or(&lower);
            // Rust's float parser accepts "inf"/"nan" words, which cannot reach here since
            // number tokens start with a digit or a dot.
            body.parse::<f64>().ok()
        };
        match magnitude {
            Some(v) => Ok(Value::Number {
                value: if negative { -v } else { v },
                text: if negative { format!("-{text}") } else { text.to_string() },
            }),
            None => Err(self.error_at(t, format!("invalid number `{text}`"))),
        }
    }
}

/// Whether an identifier is one of the float words of the text format.
fn is_special_float(id: &str) -> bool {
    matches!(id.to_ascii_lowercase().as_str(), "inf" | "infinity" | "nan")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn num(v: &Value) -> f64 {
        match v {
            Value::Number { value, .. } => *value,
            other => panic!("not a number: {other:?}"),
        }
    }

    #[test]
    fn parses_nested_messages_scalars_and_comments() {
        let text = "# a comment\nbodies {\n  name: \"torso\" # trailing\n  mass: 10\n  inertia { x: 1.0 y: -2 z:-1.5e-3 }\n}\nrotation: { z: 90 }, flag: true; hex: 0x1F\n";
        let m = parse(text, "t").unwrap();
        assert_eq!(m.fields.len(), 4);
        let bodies = &m.fields[0];
        assert_eq!((bodies.name.as_str(), bodies.line, bodies.column), ("bodies", 2, 1));
        let Value::Message(b) = &bodies.value else { panic!() };
        assert_eq!(b.fields[0].value, Value::String("torso".into()));
        assert_eq!(b.fields[1].line, 4);
        assert_eq!(num(&b.fields[1].value), 10.0);
        let Value::Message(inertia) = &b.fields[2].value else { panic!() };
        let values: Vec<f64> = inertia.fields.iter().map(|f| num(&f.value)).collect();
        assert_eq!(values, vec![1.0, -2.0, -1.5e-3]);
        assert_eq!(inertia.fields[2].column, 26);
        assert!(matches!(m.fields[1].value, Value::Message(_)));
        assert_eq!(m.fields[2].value, Value::Identifier("true".into()));
        assert_eq!(num(&m.fields[3].value), 31.0);
    }

    #[test]
    fn parses_lists_strings_and_special_numbers() {
        let text = "a: [1, -2, .5] b: [{x: 1}, <y: 2>] c: 'it\\'s' \"\\x41\\101\" d: -inf e: nan f: 1.5f g: []";
        let m = parse(text, "t").unwrap();
        let a: Vec<f64> = m.fields_named("a").map(|f| num(&f.value)).collect();
        assert_eq!(a, vec![1.0, -2.0, 0.5]);
        assert_eq!(m.fields_named("b").count(), 2);
        assert_eq!(m.fields_named("c").next().unwrap().value, Value::String("it'sAA".into()));
        assert_eq!(num(&m.fields_named("d").next().unwrap().value), f64::NEG_INFINITY);
        assert!(num(&m.fields_named("e").next().unwrap().value).is_nan());
        assert_eq!(num(&m.fields_named("f").next().unwrap().value), 1.5);
        assert_eq!(m.fields_named("g").count(), 0);
    }

    fn syntax_error(text: &str) -> (usize, usize, String) {
        match parse(text, "file.txt") {
            Err(BraxError::Syntax { location, message }) => {
                assert_eq!(location.source, "file.txt");
                (location.line, location.column, message)
            }
            other => panic!("expected a syntax error for {text:?}, got {other:?}"),
        }
    }

    #[test]
    fn reports_line_column_and_expectation() {
        let (l, c, m) = syntax_error("a {\n  b: 1\n");
        assert_eq!(l, 3);
        assert!(m.contains("expected `}` to close `a` opened at line 1"), "{m}");
        let (l, c2, m) = syntax_error("a {\n  b 1\n}");
        assert_eq!((l, c2), (2, 5));
        assert!(m.contains("expected `:` or `{` after field name `b`"), "{m}");
        let (l, _, m) = syntax_error("x: 1\ny: }\n");
        assert_eq!(l, 2);
        assert!(m.contains("expected a value"), "{m}");
        let (l, _, m) = syntax_error("x: 1.2.3");
        assert_eq!(l, 1);
        assert!(m.contains("invalid number `1.2.3`"), "{m}");
        let (_, _, m) = syntax_error("x: \"abc\ny: 1");
        assert!(m.contains("unterminated string"), "{m}");
        let (_, _, m) = syntax_error("}");
        assert!(m.contains("expected a field name, found `}`"), "{m}");
        let (_, _, m) = syntax_error("x: 1 @");
        assert!(m.contains("unexpected character '@'"), "{m}");
        let (_, _, m) = syntax_error("x: - y");
        assert!(m.contains("expected a number after `-`"), "{m}");
        let (_, _, m) = syntax_error("x: [1 2]");
        assert!(m.contains("expected `,` or `]`"), "{m}");
        let _ = c;
    }

    #[test]
    fn bounds_nesting_depth() {
        let deep = "a {".repeat(MAX_DEPTH + 1) + &"}".repeat(MAX_DEPTH + 1);
        let (_, _, m) = syntax_error(&deep);
        assert!(m.contains("nested deeper"), "{m}");
        let ok = "a {".repeat(MAX_DEPTH) + &"}".repeat(MAX_DEPTH);
        assert!(parse(&ok, "t").is_ok());
    }
}
