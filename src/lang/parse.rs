//! Stage 1: text → untyped syntax tree with source spans.
//!
//! pest pairs become an owned [`Syntax`] tree here and never leave this
//! module. Precedence comes from the operator table through a `PrattParser`.

use std::sync::OnceLock;

use pest::iterators::Pair;
use pest::pratt_parser::{Assoc, Op, PrattParser};
use pest::Parser;

pub use super::error::Span;
use super::error::{ExprError, ExprErrorKind};
use super::ops::{BinaryOp, Fixity};

#[derive(pest_derive::Parser)]
#[grammar = "../grammar/expr.pest"]
struct ExprParser;

/// An untyped syntax tree; names are not resolved yet.
#[derive(Clone, Debug, PartialEq)]
pub enum Syntax {
    Number(f64, Span),
    Name(String, Span),
    Call { name: String, name_span: Span, args: Vec<Syntax>, span: Span },
    Neg(Box<Syntax>, Span),
    Infix(BinaryOp, Box<Syntax>, Box<Syntax>, Span),
}

impl Syntax {
    pub fn span(&self) -> Span {
        match self {
            Syntax::Number(_, s) | Syntax::Name(_, s) | Syntax::Neg(_, s) => *s,
            Syntax::Call { span, .. } | Syntax::Infix(.., span) => *span,
        }
    }
}

fn pratt() -> &'static PrattParser<Rule> {
    static PRATT: OnceLock<PrattParser<Rule>> = OnceLock::new();
    PRATT.get_or_init(|| {
        // Collect infix operators from the table, lowest precedence first.
        let mut levels: Vec<(u8, Vec<Rule>)> = Vec::new();
        for op in BinaryOp::ALL {
            if let Fixity::Infix { precedence, .. } = op.fixity() {
                let rule = infix_rule(*op);
                match levels.iter_mut().find(|(p, _)| *p == precedence) {
                    Some((_, rules)) => rules.push(rule),
                    None => levels.push((precedence, vec![rule])),
                }
            }
        }
        levels.sort_by_key(|(p, _)| *p);
        let mut pratt = PrattParser::new();
        for (_, rules) in levels {
            let mut iter = rules.into_iter();
            let first = iter.next().expect("a precedence level has an operator");
            let op = iter.fold(Op::infix(first, Assoc::Left), |acc, r| acc | Op::infix(r, Assoc::Left));
            pratt = pratt.op(op);
        }
        pratt.op(Op::prefix(Rule::neg))
    })
}

fn infix_rule(op: BinaryOp) -> Rule {
    match op {
        BinaryOp::Add => Rule::add,
        BinaryOp::Sub => Rule::sub,
        BinaryOp::Mul => Rule::mul,
        BinaryOp::Div => Rule::div,
        BinaryOp::Pow => unreachable!("pow is written as a call"),
    }
}

fn rule_infix(rule: Rule) -> Option<BinaryOp> {
    BinaryOp::ALL.iter().copied().find(|op| matches!(op.fixity(), Fixity::Infix { .. }) && infix_rule(*op) == rule)
}

/// The deepest expression filterjit accepts: operators nested in one
/// another (a call's arguments, a parenthesis, each operator of a chain such
/// as a sum of many terms). Every pass over an expression (checker, printer,
/// lowering, CPU evaluator, simplifier, GP operators) recurses over it, so
/// the depth is bounded once, here, where text becomes a tree, and the
/// search keeps its offspring within it. Far beyond any useful weight (the
/// thesis's trees are under 20 deep); well within a 2 MiB thread stack in a
/// debug build (`tests/lang.rs` runs every pass at the limit).
pub const MAX_DEPTH: usize = 256;

/// Parentheses and prefix minus signs nested deeper than this stop the
/// parse before pest's own recursion sees them.
const MAX_NESTING: usize = MAX_DEPTH;

/// Parse an expression's text into a syntax tree.
pub fn parse(source: &str) -> Result<Syntax, ExprError> {
    check_nesting(source)?;
    let mut pairs = ExprParser::parse(Rule::weight, source).map_err(|e| syntax_error(e, source))?;
    let weight = pairs.next().expect("weight rule matched");
    let expr = weight.into_inner().next().expect("weight holds an expr");
    lower_expr(expr, source, 0)
}

/// An error at the first parenthesis or minus sign nested past [`MAX_NESTING`].
fn check_nesting(source: &str) -> Result<(), ExprError> {
    let (mut open, mut minus_run) = (0usize, 0usize);
    for (at, c) in source.char_indices() {
        match c {
            '(' => open += 1,
            ')' => open = open.saturating_sub(1),
            _ => {}
        }
        match c {
            '-' => minus_run += 1,
            c if c.is_whitespace() => {}
            _ => minus_run = 0,
        }
        if open + minus_run > MAX_NESTING {
            let span = Span { start: at, end: at + c.len_utf8() };
            return Err(too_deep(source, span));
        }
    }
    Ok(())
}

fn too_deep(source: &str, span: Span) -> ExprError {
    ExprError::with_kind(
        ExprErrorKind::TooDeep,
        source,
        span,
        format!("the expression nests deeper than {MAX_DEPTH} operators here; filterjit accepts at most {MAX_DEPTH}"),
    )
}

/// An `expr` pair's tree, `depth` operators below the root: its operators
/// (infix and prefix) each add at most one level to its operands'.
fn lower_expr(expr: Pair<'_, Rule>, source: &str, depth: usize) -> Result<Syntax, ExprError> {
    let pairs = expr.into_inner();
    let is_operator = |p: &Pair<'_, Rule>| !matches!(p.as_rule(), Rule::call | Rule::number | Rule::name | Rule::expr);
    let operators = pairs.clone().filter(is_operator).count();
    if depth + operators > MAX_DEPTH {
        // The first operator past the limit.
        let past = pairs.clone().filter(is_operator).nth(MAX_DEPTH.saturating_sub(depth)).expect("past the limit");
        return Err(too_deep(source, Span::from(past.as_span())));
    }
    let depth = depth + operators;
    pratt()
        .map_primary(|p| lower_primary(p, source, depth))
        .map_prefix(|op, rhs| {
            let rhs = rhs?;
            let span = Span { start: op.as_span().start(), end: rhs.span().end };
            Ok(Syntax::Neg(Box::new(rhs), span))
        })
        .map_infix(|lhs, op, rhs| {
            let (lhs, rhs) = (lhs?, rhs?);
            let binary = rule_infix(op.as_rule()).expect("infix rule maps to an operator");
            let span = Span { start: lhs.span().start, end: rhs.span().end };
            Ok(Syntax::Infix(binary, Box::new(lhs), Box::new(rhs), span))
        })
        .parse(pairs)
}

fn lower_primary(pair: Pair<'_, Rule>, source: &str, depth: usize) -> Result<Syntax, ExprError> {
    let span = Span::from(pair.as_span());
    match pair.as_rule() {
        Rule::number => {
            let value: f64 = pair
                .as_str()
                .parse()
                .map_err(|_| ExprError::at(source, span, format!("`{}` is not a number", pair.as_str())))?;
            Ok(Syntax::Number(value, span))
        }
        Rule::name => Ok(Syntax::Name(pair.as_str().to_string(), span)),
        Rule::expr => lower_expr(pair, source, depth),
        Rule::call => {
            let mut inner = pair.into_inner();
            let name = inner.next().expect("call has a name");
            if depth + 1 > MAX_DEPTH {
                return Err(too_deep(source, span));
            }
            let args = inner.map(|arg| lower_expr(arg, source, depth + 1)).collect::<Result<Vec<_>, _>>()?;
            Ok(Syntax::Call { name: name.as_str().to_string(), name_span: name.as_span().into(), args, span })
        }
        other => unreachable!("unexpected primary rule {other:?}"),
    }
}

/// pest's error as filterjit's: what was expected named in words, each
/// once, and a `)` where a bracket before the position is still open (the
/// grammar's literals are not rules, so pest cannot name it).
fn syntax_error(e: pest::error::Error<Rule>, source: &str) -> ExprError {
    use pest::error::{Error, ErrorVariant, InputLocation, LineColLocation};
    let (line, column) = match e.line_col {
        LineColLocation::Pos(p) | LineColLocation::Span(p, _) => p,
    };
    let offset = match e.location {
        InputLocation::Pos(p) | InputLocation::Span((p, _)) => p,
    };
    let e = match &e.variant {
        ErrorVariant::ParsingError { positives, .. } if !positives.is_empty() => {
            let mut expected: Vec<String> = Vec::new();
            for name in positives.iter().map(describe_rule) {
                if !expected.contains(&name) {
                    expected.push(name);
                }
            }
            if positives.contains(&Rule::number) {
                // Where an operand may start, so may a bracketed one.
                expected.push("`(`".into());
            }
            // After a whole operand (an operator would do), the innermost
            // open bracket may close there; a call's may take another argument.
            let operand_done = positives.iter().any(|r| matches!(r, Rule::add | Rule::sub | Rule::mul | Rule::div));
            if let Some(open) = innermost_open_bracket(&source[..offset.min(source.len())]).filter(|_| operand_done) {
                let in_call = source[..open].chars().next_back().is_some_and(|c| c.is_alphanumeric() || c == '_');
                if in_call {
                    expected.push("`,`".into());
                }
                expected.push("`)`".into());
            }
            let last = expected.pop().expect("positives is not empty");
            let message = match expected.is_empty() {
                true => format!("expected {last}"),
                false => format!("expected {}, or {last}", expected.join(", ")),
            };
            match pest::Position::new(source, offset) {
                Some(at) => Error::new_from_pos(ErrorVariant::CustomError { message }, at),
                None => e.renamed_rules(describe_rule),
            }
        }
        _ => e.renamed_rules(describe_rule),
    };
    let message = e.variant.message().into_owned();
    ExprError::syntax(line, column, offset, message, e.to_string())
}

/// The byte offset of the last `(` of `text` still open at its end.
fn innermost_open_bracket(text: &str) -> Option<usize> {
    let mut open = Vec::new();
    for (k, c) in text.char_indices() {
        match c {
            '(' => open.push(k),
            ')' => {
                open.pop();
            }
            _ => {}
        }
    }
    open.pop()
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
