//! Stage 1: text → untyped syntax tree with source spans.
//!
//! pest pairs become an owned [`Syntax`] tree here and never leave this
//! module. Precedence comes from the operator table through a `PrattParser`.

use std::sync::OnceLock;

use pest::iterators::{Pair, Pairs};
use pest::pratt_parser::{Assoc, Op, PrattParser};
use pest::Parser;

use super::error::ExprError;
use super::ops::{BinaryOp, Fixity};

#[derive(pest_derive::Parser)]
#[grammar = "../grammar/expr.pest"]
struct ExprParser;

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

/// Parse an expression's text into a syntax tree.
pub fn parse(source: &str) -> Result<Syntax, ExprError> {
    let mut pairs = ExprParser::parse(Rule::weight, source).map_err(|e| ExprError::from_pest(e, source))?;
    let weight = pairs.next().expect("weight rule matched");
    let expr = weight.into_inner().next().expect("weight holds an expr");
    lower_expr(expr.into_inner(), source)
}

fn lower_expr(pairs: Pairs<'_, Rule>, source: &str) -> Result<Syntax, ExprError> {
    pratt()
        .map_primary(|p| lower_primary(p, source))
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

fn lower_primary(pair: Pair<'_, Rule>, source: &str) -> Result<Syntax, ExprError> {
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
        Rule::expr => lower_expr(pair.into_inner(), source),
        Rule::call => {
            let mut inner = pair.into_inner();
            let name = inner.next().expect("call has a name");
            let args = inner.map(|arg| lower_expr(arg.into_inner(), source)).collect::<Result<Vec<_>, _>>()?;
            Ok(Syntax::Call { name: name.as_str().to_string(), name_span: name.as_span().into(), args, span })
        }
        other => unreachable!("unexpected primary rule {other:?}"),
    }
}
