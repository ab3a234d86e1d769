//! Errors in expression text, as data: a kind, a position and a message.
//! `Display` renders them with the offending line and a caret.

use pest::error::{Error as PestError, ErrorVariant, InputLocation, LineColLocation};

use super::parse::{Rule, Span};

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
    pub(crate) fn from_pest(e: PestError<Rule>, _source: &str) -> Self {
        let (line, column) = match e.line_col {
            LineColLocation::Pos(p) | LineColLocation::Span(p, _) => p,
        };
        let offset = match e.location {
            InputLocation::Pos(p) | InputLocation::Span((p, _)) => p,
        };
        let e = e.renamed_rules(describe_rule);
        let message = e.variant.message().into_owned();
        ExprError { kind: ExprErrorKind::Syntax, line, column, offset, message, rendered: e.to_string() }
    }

    pub(crate) fn at(source: &str, span: Span, message: String) -> Self {
        Self::with_kind(ExprErrorKind::Syntax, source, span, message)
    }

    pub(crate) fn with_kind(kind: ExprErrorKind, source: &str, span: Span, message: String) -> Self {
        let pest_span = pest::Span::new(source, span.start, span.end)
            .or_else(|| pest::Span::new(source, span.start, span.start))
            .expect("span lies inside the source");
        let e: PestError<Rule> =
            PestError::new_from_span(ErrorVariant::CustomError { message: message.clone() }, pest_span);
        let (line, column) = match e.line_col {
            LineColLocation::Pos(p) | LineColLocation::Span(p, _) => p,
        };
        ExprError { kind, line, column, offset: span.start, message, rendered: e.to_string() }
    }
}

fn describe_rule(rule: &Rule) -> String {
    match rule {
        Rule::EOI => "end of input".into(),
        Rule::expr | Rule::primary => "an expression".into(),
        Rule::add | Rule::sub | Rule::mul | Rule::div => "an operator (+ - * /)".into(),
        Rule::neg => "`-`".into(),
        Rule::call => "a call".into(),
        Rule::name => "a name".into(),
        Rule::number => "a number".into(),
        other => format!("{other:?}"),
    }
}
