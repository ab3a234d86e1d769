//! HDR-FLIP against the reference implementation's values
//! (`flip-evaluator` 1.7, made by `tests/data/flip/make.py`).

use filterjit::flip;

struct Case {
    name: String,
    width: usize,
    height: usize,
    mean: f64,
    reference: Vec<[f32; 3]>,
    test: Vec<[f32; 3]>,
    error: Vec<f32>,
}

fn cases() -> Vec<Case> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/flip");
    let list = std::fs::read_to_string(dir.join("cases.txt")).unwrap();
    list.lines()
        .map(|line| {
            let fields: Vec<&str> = line.split_whitespace().collect();
            let (width, height): (usize, usize) = (fields[1].parse().unwrap(), fields[2].parse().unwrap());
            let bytes = std::fs::read(dir.join(format!("{}.f32", fields[0]))).unwrap();
            let values: Vec<f32> =
                bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
            let n = width * height;
            assert_eq!(values.len(), 7 * n, "{}: reference, test and map", fields[0]);
            let rgb = |s: &[f32]| s.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>();
            Case {
                name: fields[0].to_string(),
                width,
                height,
                mean: fields[3].parse().unwrap(),
                reference: rgb(&values[..3 * n]),
                test: rgb(&values[3 * n..6 * n]),
                error: values[6 * n..].to_vec(),
            }
        })
        .collect()
}

#[test]
fn hdr_flip_matches_the_reference_implementation() {
    let cases = cases();
    assert!(cases.len() >= 2);
    for c in cases {
        let map = flip::hdr_flip(&c.reference, &c.test, c.width, c.height);
        let worst = map.error.iter().zip(&c.error).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst <= 1e-5, "{}: a pixel differs by {worst} from the reference implementation's", c.name);
        assert!((map.mean() - c.mean).abs() <= 1e-6, "{}: mean {} against {}", c.name, map.mean(), c.mean);
        // The map is not trivially small: the cases have visible errors.
        assert!(c.mean > 0.1, "{}", c.name);
    }
}

#[test]
fn identical_images_have_no_flip_error() {
    let c = &cases()[0];
    let map = flip::hdr_flip(&c.reference, &c.reference, c.width, c.height);
    assert!(map.error.iter().all(|&e| e == 0.0), "max {}", map.error.iter().copied().fold(0.0f32, f32::max));
}
