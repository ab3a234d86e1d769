//! Stage 2: untyped syntax → typed [`Expr`]: resolves names against the
//! operator table and checks types and arities, reporting positions.

use super::error::{ExprError, ExprErrorKind};
use super::expr::{literal_in_range, Expr};
use super::ops::{CallOp, Feature, PairOp, Terminal, UnaryOp};
use super::parse::{parse, Span, Syntax};
use crate::semantics;

/// Parse and type-check an expression's text.
pub fn parse_expr(source: &str) -> Result<Expr, ExprError> {
    let syntax = parse(source)?;
    check(&syntax, source)
}

/// Type-check a syntax tree; `source` is the text it was parsed from, for messages.
pub fn check(syntax: &Syntax, source: &str) -> Result<Expr, ExprError> {
    Checker { source }.scalar(syntax)
}

struct Checker<'s> {
    source: &'s str,
}

impl Checker<'_> {
    fn error(&self, kind: ExprErrorKind, span: Span, message: String) -> ExprError {
        ExprError::with_kind(kind, self.source, span, message)
    }

    fn scalar(&self, node: &Syntax) -> Result<Expr, ExprError> {
        match node {
            Syntax::Number(value, span) => {
                if !literal_in_range(*value) {
                    return Err(self.error(
                        ExprErrorKind::Literal,
                        *span,
                        format!("literal out of range: literals must be finite and at most {:e}", semantics::BIG),
                    ));
                }
                Ok(Expr::Const(*value))
            }
            Syntax::Name(name, span) => match Terminal::from_name(name) {
                Some(Terminal::Const(c)) => Ok(Expr::Const(c)),
                Some(Terminal::Var(v)) => Ok(Expr::Var(v)),
                Some(Terminal::Feature(f)) => Err(self.error(
                    ExprErrorKind::Type,
                    *span,
                    format!(
                        "`{f}` is a vector feature, but a scalar is expected here; \
                         compare it between the two pixels with {}({f})",
                        pair_names()
                    ),
                )),
                None => Err(self.unknown(name, *span)),
            },
            Syntax::Neg(a, _) => Ok(Expr::unary(UnaryOp::Neg, self.scalar(a)?)),
            Syntax::Infix(op, a, b, _) => Ok(Expr::binary(*op, self.scalar(a)?, self.scalar(b)?)),
            Syntax::Call { name, name_span, args, span } => {
                let Some(op) = CallOp::from_name(name) else {
                    let message = match Terminal::from_name(name) {
                        Some(_) => format!("`{name}` is a terminal, not an operator; it takes no arguments"),
                        None => return Err(self.unknown(name, *name_span)),
                    };
                    return Err(self.error(ExprErrorKind::UnknownName, *name_span, message));
                };
                let arity = op.arguments().len();
                let pair_shorthand = matches!(op, CallOp::Pair(_)) && args.len() == 1;
                if args.len() != arity && !pair_shorthand {
                    let expected = match op {
                        CallOp::Pair(_) => "1 or 2 arguments (features)".to_string(),
                        _ => format!("{arity} argument{}", if arity == 1 { "" } else { "s" }),
                    };
                    return Err(self.error(
                        ExprErrorKind::Arity,
                        *span,
                        format!("`{name}` takes {expected}, found {}", args.len()),
                    ));
                }
                match op {
                    CallOp::Unary(u) => Ok(Expr::unary(u, self.scalar(&args[0])?)),
                    CallOp::Binary(b) => Ok(Expr::binary(b, self.scalar(&args[0])?, self.scalar(&args[1])?)),
                    CallOp::Pair(p) => {
                        let i = self.feature(p, &args[0])?;
                        let j = match args.get(1) {
                            Some(arg) => self.feature(p, arg)?,
                            None => i,
                        };
                        Ok(Expr::Pair(p, i, j))
                    }
                }
            }
        }
    }

    fn feature(&self, op: PairOp, node: &Syntax) -> Result<Feature, ExprError> {
        if let Syntax::Name(name, span) = node {
            return match Terminal::from_name(name) {
                Some(Terminal::Feature(f)) => Ok(f),
                Some(_) => Err(self.error(
                    ExprErrorKind::Type,
                    *span,
                    format!(
                        "`{op}` compares vector features, but `{name}` is a scalar; expected one of: {}",
                        feature_names()
                    ),
                )),
                None => Err(self.unknown(name, *span)),
            };
        }
        Err(self.error(
            ExprErrorKind::Type,
            node.span(),
            format!("`{op}` takes feature names, not a scalar expression; expected one of: {}", feature_names()),
        ))
    }

    fn unknown(&self, name: &str, span: Span) -> ExprError {
        self.error(
            ExprErrorKind::UnknownName,
            span,
            format!(
                "unknown name `{name}`; expected a feature ({}), a variable ({}), `pi`, or an operator call",
                feature_names(),
                super::ops::ScalarVar::ALL.iter().map(|v| v.name()).collect::<Vec<_>>().join(", ")
            ),
        )
    }
}

fn feature_names() -> String {
    Feature::ALL.iter().map(|f| f.name()).collect::<Vec<_>>().join(", ")
}

fn pair_names() -> String {
    PairOp::ALL.iter().map(|p| p.name()).collect::<Vec<_>>().join("/")
}
