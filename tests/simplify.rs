//! The simplifier: every rule keeps the CPU evaluator's weights and domain
//! flags; simplified expressions are never costlier, and give the same
//! fitness on rendered built-in scenes.

use filterjit::cpu;
use filterjit::lang::random::Alphabet;
use filterjit::lang::{parse_expr, BinaryOp, Expr, UnaryOp};
use filterjit::rng::Rng;
use filterjit::simplify::{self, RULES, WEIGHT_TOLERANCE};
use filterjit::Scene;

use crate::common::{env_usize, synthetic_scene};

/// (weight, flags) of `expr` at several centre/neighbour pairs.
fn evaluations(expr: &Expr, scene: &Scene) -> Vec<(f64, u32)> {
    let n = scene.pixels();
    (0..n)
        .step_by(7)
        .flat_map(|i| [(i, i), (i, (i * 13 + 5) % n)])
        .map(|(i, j)| cpu::weight_at(expr, scene, i, j))
        .collect()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= WEIGHT_TOLERANCE * a.abs().max(1.0)
}

/// Operands for the pattern variables: random expressions, and values at
/// the edges of the semantics (zero, the saturation bound, raw variances,
/// subterms that raise flags).
fn operands(rng: &mut Rng, count: usize) -> Vec<Expr> {
    let mut out: Vec<Expr> = [
        "0",
        "1",
        "-1000000000000000",
        "colorVariance",
        "1e-20 * distance2(normal)",
        "sqrt(-dot(normal, texture))",
        "pow(-distance2(normal), 0.5)",
        "distance2(normal) * 1000000000000",
        "exp(-distance1(color))",
        "distance2(normal) / distance1(texture)",
        "pow(distance1(color), 3)",
        "abs(sin(distance2(pixel)))",
        "0.5 * sin(distance2(pixel))",
        "epanechnikov(dot(normal)) - 1.5",
    ]
    .iter()
    .map(|t| parse_expr(t).unwrap())
    .collect();
    let alphabet = Alphabet::full();
    while out.len() < count {
        let depth = 1 + rng.below(4);
        out.push(alphabet.grow(rng, depth));
    }
    out
}

#[test]
fn every_rule_keeps_weights_and_flags_on_the_cpu() {
    let scene = synthetic_scene(9, 7, 4);
    let mut rng = Rng::seeded(31);
    let xs = operands(&mut rng, env_usize("FILTERJIT_RULE_CASES", 60));
    // Constants for ?p and ?q: powers of two (the scaling rules) and others.
    let constants = [0.5, 2.0, 27.0, 0.1, 3.7, 1.0, 0.25, 1024.0, 3.5, 2.0f64.powi(-20)];
    for (name, lhs, rhs, condition) in RULES {
        let mut checked = 0;
        for (k, x) in xs.iter().enumerate() {
            let y = &xs[(k * 7 + 3) % xs.len()];
            // The first (p, q) in a rotation of the constants for which the rule may fire.
            let pairs = (0..constants.len() * constants.len()).map(|n| (n + k) % (constants.len() * constants.len()));
            let Some((p, q)) = pairs
                .map(|n| (Expr::Const(constants[n / constants.len()]), Expr::Const(constants[n % constants.len()])))
                .find(|(p, q)| simplify::condition_holds_for(*condition, x, p, q))
            else {
                continue;
            };
            let values = [("?x", x), ("?y", y), ("?p", &p), ("?q", &q)];
            let (before, after) = (simplify::instantiate_with(lhs, &values), simplify::instantiate_with(rhs, &values));
            for ((wb, fb), (wa, fa)) in evaluations(&before, &scene).into_iter().zip(evaluations(&after, &scene)) {
                assert!(close(wb, wa), "rule {name}: `{before}` gives {wb:e}, `{after}` gives {wa:e}");
                assert_eq!(fb, fa, "rule {name}: flags of `{before}` and `{after}` differ");
            }
            checked += 1;
        }
        assert!(checked >= 5, "rule {name} was checked on only {checked} operands");
    }
}

/// The analysis behind the conditional rules and range folding is sound:
/// every value lies in the range it states, a class it calls constant has
/// that value, and one it says never flags never does.
#[test]
fn ranges_constants_and_flag_predictions_hold_on_the_cpu() {
    let scene = synthetic_scene(9, 7, 6);
    let mut rng = Rng::seeded(12);
    let mut exprs = operands(&mut rng, env_usize("FILTERJIT_RANGE_CASES", 400));
    // Compositions of the edge cases, where bounds meet saturation and the window kernels' supports.
    let edges = exprs[..14].to_vec();
    for (k, a) in edges.iter().enumerate() {
        let b = &edges[(k * 5 + 1) % edges.len()];
        for op in BinaryOp::ALL {
            exprs.push(Expr::binary(*op, a.clone(), b.clone()));
        }
        for op in UnaryOp::ALL {
            exprs.push(Expr::unary(*op, a.clone()));
        }
    }
    let (mut never_flag, mut narrow) = (0, 0);
    for expr in &exprs {
        let facts = simplify::facts(expr);
        never_flag += usize::from(!facts.may_flag);
        narrow += usize::from(facts.range != simplify::Range::ANY);
        // A constant class holds its folded literal too, rounded to f32 once
        // (see WEIGHT_TOLERANCE), and so may its range.
        let slack = |bound: f64| WEIGHT_TOLERANCE * bound.abs().max(1.0);
        for (w, flags) in evaluations(expr, &scene) {
            assert!(
                facts.range.lo - slack(facts.range.lo) <= w && w <= facts.range.hi + slack(facts.range.hi),
                "`{expr}` gives {w:e}, outside its range [{:e}, {:e}]",
                facts.range.lo,
                facts.range.hi
            );
            if let Some(c) = facts.constant {
                assert!(close(w, c), "`{expr}` gives {w:e} but was called the constant {c:e}");
            }
            assert!(facts.may_flag || flags == 0, "`{expr}` raised flags {flags} but was said never to");
        }
    }
    // The check means something only if the analysis claims something.
    assert!(never_flag * 2 > exprs.len() && narrow * 4 > exprs.len(), "{never_flag} never flag, {narrow} narrow");
}

#[test]
fn simplified_random_expressions_agree_and_are_never_costlier() {
    let scene = synthetic_scene(9, 7, 5);
    let mut rng = Rng::seeded(8);
    let alphabet = Alphabet::full();
    let count = env_usize("FILTERJIT_RANDOM_EXPRS", 40) * 5;
    let (mut agree, mut total, mut shorter) = (0usize, 0usize, 0usize);
    for _ in 0..count {
        // Bloat the way GP does: identities and literal arithmetic around random terms.
        let depth = 2 + rng.below(4);
        let core = alphabet.grow(&mut rng, depth);
        let bloated = Expr::binary(
            BinaryOp::Div,
            Expr::binary(BinaryOp::Add, core, Expr::binary(BinaryOp::Mul, Expr::Const(0.0), Expr::Const(3.0))),
            Expr::binary(BinaryOp::Pow, Expr::Const(1.0), Expr::unary(UnaryOp::Abs, Expr::Const(2.0))),
        );
        let simplified = simplify::simplify(&bloated);
        assert!(simplify::kernel_cost(&simplified) <= simplify::kernel_cost(&bloated), "`{bloated}` → `{simplified}`");
        assert_eq!(parse_expr(&simplified.to_string()).unwrap(), simplified, "prints and parses back");
        shorter += usize::from(simplified.len() < bloated.len());
        for ((wb, fb), (wa, fa)) in evaluations(&bloated, &scene).into_iter().zip(evaluations(&simplified, &scene)) {
            total += 1;
            agree += usize::from(close(wb, wa) && fb == fa);
        }
    }
    // Folding rounds a constant subtree to f32 once where the CPU reference
    // rounds each literal: a long chain through sin or exp can amplify that
    // past the tolerance, as it does between the CPU and the GPU.
    let fraction = agree as f64 / total as f64;
    assert!(fraction >= 0.99, "only {:.2}% of weights agree", 100.0 * fraction);
    assert_eq!(shorter, count, "every bloated expression got shorter");
}

#[test]
fn the_default_runs_bloat_is_removed() {
    let raw = "exp(-(pow(distance1(pixel), 2) / (exp(-(pow(distance2(texture), 2) + pow(distance1(normal, color), distance2(dovGradient, color)) / 1)) * pow(3, 2)) + pow(3, 2) / 1))";
    let simplified = simplify::simplify(&parse_expr(raw).unwrap());
    assert_eq!(
        simplified.to_string(),
        "exp(-(pow(distance1(pixel), 2) / (exp(-(pow(distance2(texture), 2) + pow(distance1(normal, color), distance2(dovGradient, color)))) * 9) + 9))"
    );
}

/// A constant a hair below 1 is 1 to the f32 literals the kernels hold, so
/// `x * c` and `x` meet in one class; the range analysis narrowed that class
/// by the factor c forever, and `evolve` hung at the end of a run simplifying
/// its hall of fame. Both expressions came out of that run.
#[test]
fn a_factor_a_hair_below_one_does_not_narrow_a_range_forever() {
    let exprs = [
        "(distance1(color) * exp(-0.000000000000001)) / 1",
        "exp(-(distance1(color) / (62.8 * sqrt(colorVariance) + 3) + (exp(-(distance1(color) / (exp(-(pow(0.1, 11) / (2 * pow(62.8, 2)))) * pow(0.1, 2)) + 1 + pow(0.1, 2) / (2 * pow(62.8, 2)) / 2)) + (1 + 1)) / 1 + distance2(worldPosition) / (2 / (pow(distance1(pixel), 2) * 1))))",
    ];
    for text in exprs {
        let expr = parse_expr(text).unwrap();
        let (done, result) = std::sync::mpsc::channel();
        std::thread::spawn(move || done.send(simplify::simplify(&expr)));
        let simplified = result
            .recv_timeout(std::time::Duration::from_secs(60))
            .unwrap_or_else(|_| panic!("simplifying `{text}` did not finish in a minute"));
        assert!(simplified.len() < parse_expr(text).unwrap().len(), "{text} -> {simplified}");
    }
}

#[test]
fn simplified_expressions_score_the_same_fitness_on_built_in_scenes() {
    use filterjit::fitness::{Scorer, Settings};
    use filterjit::gp::Evaluator;
    let gpu = crate::common::gpu();
    let (training, test) = crate::evolve::datasets();
    let raw: Vec<Expr> = filterjit::bench::BLOATED.iter().map(|t| parse_expr(t).unwrap()).collect();
    let simplified: Vec<Expr> = raw.iter().map(simplify::simplify).collect();
    for (r, s) in raw.iter().zip(&simplified) {
        assert!(s.len() < r.len(), "`{r}` did not get shorter");
    }
    let mut request = filterjit::scene::Request { reference: true, ..Default::default() };
    for e in &raw {
        request.features.extend(e.features());
        request.variances.extend(e.variables());
    }
    let scenes = [training, test].iter().map(|d| filterjit::scene::load(d, &request).unwrap()).collect::<Vec<_>>();
    let mut evaluator = Scorer::new(&gpu, scenes, &Settings::window(2, 2)).unwrap();
    let before = evaluator.evaluate(&filterjit::gp::Candidate::at_run_radius(&raw)).unwrap();
    let after = evaluator.evaluate(&filterjit::gp::Candidate::at_run_radius(&simplified)).unwrap();
    for ((r, b), a) in raw.iter().zip(&before).zip(&after) {
        assert_eq!(b.invalid, a.invalid, "`{r}`");
        assert!(
            (b.value - a.value).abs() <= 1e-5 * b.value.abs().max(1e-3),
            "`{r}`: fitness {} then {}",
            b.value,
            a.value
        );
    }
}

#[test]
fn a_run_that_simplifies_offspring_has_a_hall_of_fame_whose_simplified_forms_score_the_same() {
    use filterjit::fitness::{Scorer, Settings};
    use filterjit::gp::Evaluator;
    let (training, test) = crate::evolve::datasets();
    let dir = crate::evolve::temp_dir("simplify-offspring");
    let settings = filterjit::gp::Settings { simplify_offspring: true, ..crate::evolve::small() };
    crate::evolve::run(&dir, settings, crate::evolve::config(training, test), false, None).expect("finished");
    let text = std::fs::read_to_string(dir.join(filterjit::evolve::HALL_OF_FAME_FILE)).unwrap();
    let raw: Vec<Expr> = filterjit::named::NamedFile::parse(&text)
        .unwrap()
        .resolved()
        .iter()
        .map(|(_, t)| parse_expr(t).unwrap())
        .collect();
    let noted = text.lines().filter(|l| l.starts_with("# simplified (length ")).count();
    assert_eq!(noted, raw.len(), "every entry carries its simplified form");
    let simplified: Vec<Expr> = raw.iter().map(simplify::simplify).collect();
    let mut request = filterjit::scene::Request { reference: true, ..Default::default() };
    for e in &raw {
        request.features.extend(e.features());
        request.variances.extend(e.variables());
    }
    let gpu = crate::common::gpu();
    let scenes = vec![filterjit::scene::load(training, &request).unwrap()];
    let mut evaluator = Scorer::new(&gpu, scenes, &Settings::window(2, 2)).unwrap();
    let before = evaluator.evaluate(&filterjit::gp::Candidate::at_run_radius(&raw)).unwrap();
    let after = evaluator.evaluate(&filterjit::gp::Candidate::at_run_radius(&simplified)).unwrap();
    for ((r, b), a) in raw.iter().zip(&before).zip(&after) {
        assert_eq!(b.invalid, a.invalid, "`{r}`");
        assert!((b.value - a.value).abs() <= 1e-5 * b.value.abs().max(1e-3), "`{r}`: {} then {}", b.value, a.value);
    }
}
