//! The expression language: operator table, grammar-driven parser, type
//! checker and canonical printer. No I/O, no GPU.

pub mod check;
pub mod error;
pub mod expr;
pub mod latex;
pub mod ops;
pub mod parse;
pub mod random;

pub use check::parse_expr;
pub use error::{ExprError, ExprErrorKind};
pub use expr::{terminal_usage, Expr};
pub use latex::latex;
pub use ops::{BinaryOp, Feature, FeatureSource, PairOp, ScalarVar, Type, UnaryOp};
pub use parse::MAX_DEPTH;
