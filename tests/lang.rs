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

/// `exp(` nested `depth` deep around a pair operator: `depth + 1` levels as the parser counts them.
fn nested(depth: usize) -> String {
    format!("{}distance2(normal){}", "exp(".repeat(depth), ")".repeat(depth))
}

/// A sum of `terms` terms: `terms - 1` operators in a chain.
fn long_sum(terms: usize) -> String {
    vec!["colorVariance"; terms].join(" + ")
}

/// At the depth limit every pass works, on a test thread's 2 MiB stack;
/// one level past it the parser says where, and nothing recurses further.
#[test]
fn expressions_at_the_depth_limit_go_through_every_pass() {
    use filterjit::lang::MAX_DEPTH;
    let scene = crate::common::synthetic_scene(8, 8, 1);
    for text in [nested(MAX_DEPTH - 1), long_sum(MAX_DEPTH + 1)] {
        let expr = parse_expr(&text).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(expr.depth(), MAX_DEPTH);
        assert_eq!(parse_expr(&expr.to_string()).unwrap(), expr, "print → parse round-trips");
        filterjit::jit::compile(&expr, filterjit::jit::KernelSpec::default()).unwrap();
        let simplified = filterjit::simplify::simplify(&expr);
        parse_expr(&simplified.to_string()).unwrap();
        filterjit::cpu::filter(&expr, &scene, 1).unwrap();
        filterjit::lang::latex(&expr);
        filterjit::cost::model(&expr, &filterjit::pipeline::FilterPipeline::WINDOW, 2);
    }
}

#[test]
fn expressions_past_the_depth_limit_fail_with_a_position_not_a_crash() {
    use filterjit::lang::MAX_DEPTH;
    let cases = [
        // One level past the limit: the call that opens it.
        (nested(MAX_DEPTH), 1 + 4 * MAX_DEPTH + "distance2".len()),
        // The operator past the limit in a long chain (the issue's 20,000 terms).
        (long_sum(20_000), 1 + MAX_DEPTH * "colorVariance + ".len() + "colorVariance ".len()),
        // Far past it: stopped before the parser recurses (4,000 and 50,000 deep).
        (nested(4_000), 1 + 4 * MAX_DEPTH + 3),
        (nested(50_000), 1 + 4 * MAX_DEPTH + 3),
        (format!("{}1", "-".repeat(10_000)), 1 + MAX_DEPTH),
    ];
    for (text, column) in cases {
        let err = parse_expr(&text).unwrap_err();
        assert_eq!(err.kind, ExprErrorKind::TooDeep, "{}", err.message);
        assert_eq!((err.line, err.column), (1, column), "{}…", &text[..40]);
        assert!(err.message.contains(&MAX_DEPTH.to_string()), "{}", err.message);
    }
}
