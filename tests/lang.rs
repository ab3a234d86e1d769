//! The expression language: data-driven parse cases, exact round trips, the thesis corpus.

use filterjit::corpus;
use filterjit::lang::random::Alphabet;
use filterjit::lang::{parse_expr, ExprErrorKind};
use filterjit::rng::Rng;

use crate::common::env_usize;

const OK: &str = include_str!("data/parse/ok.txt");
const ERR: &str = include_str!("data/parse/err.txt");

#[test]
fn ok_cases_parse_to_their_canonical_form() {
    let mut count = 0;
    for line in OK.lines().filter(|l| !l.trim().is_empty() && !l.starts_with('#')) {
        let (input, canonical) = match line.split_once("=>") {
            Some((i, c)) => (i, c.trim()),
            None => (line, line.trim()),
        };
        let expr = parse_expr(input).unwrap_or_else(|e| panic!("`{input}` must parse:\n{e}"));
        assert_eq!(expr.to_string(), canonical, "canonical form of `{input}`");
        assert_eq!(parse_expr(&expr.to_string()).unwrap(), expr, "round trip of `{input}`");
        count += 1;
    }
    assert!(count > 20);
}

#[test]
fn err_cases_fail_with_kind_position_and_message() {
    let blocks: Vec<&str> = ERR.split("\n\n").map(str::trim).filter(|b| !b.is_empty() && !b.starts_with('#')).collect();
    assert!(blocks.len() > 15);
    for block in blocks {
        let (input, expectation) = block.split_once('\n').expect("input line, then expectation line");
        let input = input.replace("\\n", "\n");
        let (kind, rest) = expectation.split_once(" at ").expect("`kind at line:col: fragment`");
        let (position, fragment) = rest.split_once(": ").expect("position, then fragment");
        let (line, column) = position.split_once(':').unwrap();
        let error = match parse_expr(&input) {
            Ok(e) => panic!("`{input}` must be rejected, but parsed as `{e}`"),
            Err(e) => e,
        };
        let expected_kind = match kind {
            "Syntax" => ExprErrorKind::Syntax,
            "Type" => ExprErrorKind::Type,
            "UnknownName" => ExprErrorKind::UnknownName,
            "Arity" => ExprErrorKind::Arity,
            "Literal" => ExprErrorKind::Literal,
            other => panic!("unknown kind {other}"),
        };
        assert_eq!(error.kind, expected_kind, "kind for `{input}`:\n{error}");
        assert_eq!(
            (error.line.to_string(), error.column.to_string()),
            (line.to_string(), column.to_string()),
            "position for `{input}`:\n{error}"
        );
        assert!(error.message.contains(fragment), "message for `{input}` should contain `{fragment}`:\n{error}");
        let rendered = error.to_string();
        assert!(rendered.contains(&format!("{line}:{column}")), "rendered error names the position:\n{rendered}");
    }
}

#[test]
fn random_expressions_round_trip_exactly() {
    let count = env_usize("FILTERJIT_ROUNDTRIP_CASES", 3000);
    let alphabet = Alphabet::full();
    let mut rng = Rng::seeded(2026);
    for _ in 0..count {
        let depth = 1 + rng.below(8);
        let expr = alphabet.grow(&mut rng, depth);
        let text = expr.to_string();
        let back = parse_expr(&text).unwrap_or_else(|e| panic!("printed form of {expr:?} does not parse:\n{e}"));
        assert_eq!(back, expr, "parse(print(e)) != e for `{text}`");
    }
}

#[test]
fn thesis_expressions_parse_print_and_round_trip() {
    let named = corpus::named();
    for name in ["thesis1", "thesis2", "thesis3"] {
        let (_, text) = named.iter().find(|(n, _)| *n == name).expect("thesis expression shipped");
        let expr = parse_expr(text).unwrap_or_else(|e| panic!("{name}:\n{e}"));
        assert_eq!(expr.to_string(), *text, "{name} is stored in canonical form");
    }
    // The issue's own spelling of equation 4.1.
    let issue = "exp(-(distance2(depth) + distance2(normal) + 2 * abs(dot(texture)) + distance2(color) + distanceMax(texture) + distance1(normal))) * biweight(-(pow(distance2(directIllumination), 2) * 2))";
    assert_eq!(parse_expr(issue).unwrap(), parse_expr(corpus::lookup("thesis1").unwrap()).unwrap());
}

#[test]
fn every_shipped_expression_is_valid() {
    for (name, text) in corpus::named() {
        parse_expr(text).unwrap_or_else(|e| panic!("@{name}:\n{e}"));
    }
}
