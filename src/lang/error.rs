//! Errors in expression text, as data: a kind, a position and a message.
//! `Display` renders them with the offending line and a caret.

use pest::error::{Error as PestError, ErrorVariant, LineColLocation};

/// Byte range in the source text.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Span {
    pub start: usize,
    pub end: usize,
}

impl From<pest::Span<'_>> for Span {
    fn from(s: pest::Span<'_>) -> Self {
        Span { start: s.start(), end: s.end() }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExprErrorKind {
    /// The text does not follow the grammar.
    Syntax,
    /// A name that is no operator, feature, variable or constant.
    UnknownName,
    /// An operator called with the wrong number of arguments.
    Arity,
    /// A vector where a scalar belongs, or the reverse.
    Type,
    /// A literal outside the representable range.
    Literal,
    /// Operators nested deeper than [`super::parse::MAX_DEPTH`].
    TooDeep,
}

#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{rendered}")]
pub struct ExprError {
    pub kind: ExprErrorKind,
    /// 1-based line of the error's start.
    pub line: usize,
    /// 1-based column (in characters) of the error's start.
    pub column: usize,
    /// Byte offset of the error's start.
    pub offset: usize,
    /// What went wrong, without position.
    pub message: String,
    rendered: String,
}

impl ExprError {
    /// A syntax error the parser found, already rendered (`super::parse` owns the grammar's words).
    pub(crate) fn syntax(line: usize, column: usize, offset: usize, message: String, rendered: String) -> Self {
        ExprError { kind: ExprErrorKind::Syntax, line, column, offset, message, rendered }
    }

    pub(crate) fn at(source: &str, span: Span, message: String) -> Self {
        Self::with_kind(ExprErrorKind::Syntax, source, span, message)
    }

    pub(crate) fn with_kind(kind: ExprErrorKind, source: &str, span: Span, message: String) -> Self {
        let pest_span = pest::Span::new(source, span.start, span.end)
            .or_else(|| pest::Span::new(source, span.start, span.start))
            .expect("span lies inside the source");
        // Rendered by pest's caret printer; a custom message names no grammar rule.
        let e: PestError<()> =
            PestError::new_from_span(ErrorVariant::CustomError { message: message.clone() }, pest_span);
        let (line, column) = match e.line_col {
            LineColLocation::Pos(p) | LineColLocation::Span(p, _) => p,
        };
        ExprError { kind, line, column, offset: span.start, message, rendered: e.to_string() }
    }
}
