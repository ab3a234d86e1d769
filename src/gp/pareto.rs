//! Non-dominated sorting and crowding distance (Deb et al., NSGA-II, 2002)
//! over points of objectives to minimise: what the multi-objective search
//! selects by. Pure functions of the points; ties keep index order, so a
//! run is deterministic.

/// Whether `a` is at least as good as `b` in every objective and better in one.
pub fn dominates(a: &[f64], b: &[f64]) -> bool {
    let mut better = false;
    for (x, y) in a.iter().zip(b) {
        if x > y {
            return false;
        }
        better |= x < y;
    }
    better
}

/// The front of every point: 0 for the non-dominated ones, 1 for those
/// dominated only by front 0, and so on.
pub fn fronts(points: &[Vec<f64>]) -> Vec<usize> {
    let n = points.len();
    let mut dominated_by = vec![0usize; n];
    let mut dominates_list: Vec<Vec<usize>> = vec![Vec::new(); n];
    for i in 0..n {
        for j in 0..n {
            if i != j && dominates(&points[i], &points[j]) {
                dominates_list[i].push(j);
                dominated_by[j] += 1;
            }
        }
    }
    let mut rank = vec![usize::MAX; n];
    let mut current: Vec<usize> = (0..n).filter(|&i| dominated_by[i] == 0).collect();
    let mut level = 0;
    while !current.is_empty() {
        let mut next = Vec::new();
        for &i in &current {
            rank[i] = level;
            for &j in &dominates_list[i] {
                dominated_by[j] -= 1;
                if dominated_by[j] == 0 {
                    next.push(j);
                }
            }
        }
        next.sort_unstable();
        current = next;
        level += 1;
    }
    rank
}

/// Crowding distance of every point within its front: the sum over
/// objectives of the normalised gap between its neighbours; a front's
/// extremes get infinity, so they are always kept.
pub fn crowding(points: &[Vec<f64>], rank: &[usize]) -> Vec<f64> {
    let n = points.len();
    let mut distance = vec![0.0; n];
    let objectives = points.first().map_or(0, Vec::len);
    let columns: Vec<Vec<f64>> = (0..objectives).map(|o| points.iter().map(|p| p[o]).collect()).collect();
    let fronts = rank.iter().copied().filter(|&r| r != usize::MAX).max().map_or(0, |m| m + 1);
    for front in 0..fronts {
        let members: Vec<usize> = (0..n).filter(|&i| rank[i] == front).collect();
        for column in &columns {
            let value = |i: usize| column[i];
            let mut sorted = members.clone();
            sorted.sort_by(|&a, &b| value(a).total_cmp(&value(b)).then(a.cmp(&b)));
            let (first, last) = (sorted[0], sorted[sorted.len() - 1]);
            let span = value(last) - value(first);
            distance[first] = f64::INFINITY;
            distance[last] = f64::INFINITY;
            if span <= 0.0 || !span.is_finite() {
                continue;
            }
            for w in sorted.windows(3) {
                distance[w[1]] += (value(w[2]) - value(w[0])) / span;
            }
        }
    }
    distance
}

/// Indices best first: by front, then by crowding distance (larger first), then by index.
pub fn order(points: &[Vec<f64>]) -> Vec<usize> {
    let rank = fronts(points);
    let distance = crowding(points, &rank);
    let mut indices: Vec<usize> = (0..points.len()).collect();
    indices.sort_by(|&a, &b| rank[a].cmp(&rank[b]).then(distance[b].total_cmp(&distance[a])).then(a.cmp(&b)));
    indices
}

/// Every point's place in [`order`] (0 = best): what tournaments compare.
pub fn places(points: &[Vec<f64>]) -> Vec<usize> {
    let mut place = vec![0; points.len()];
    for (k, i) in order(points).into_iter().enumerate() {
        place[i] = k;
    }
    place
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(v: &[(f64, f64)]) -> Vec<Vec<f64>> {
        v.iter().map(|&(a, b)| vec![a, b]).collect()
    }

    #[test]
    fn fronts_peel_non_dominated_layers() {
        let points = p(&[(1.0, 5.0), (2.0, 2.0), (5.0, 1.0), (3.0, 3.0), (6.0, 6.0), (2.0, 2.0)]);
        assert_eq!(fronts(&points), vec![0, 0, 0, 1, 2, 0]);
        assert!(dominates(&[1.0, 1.0], &[1.0, 2.0]));
        assert!(!dominates(&[1.0, 1.0], &[1.0, 1.0]));
        assert!(!dominates(&[1.0, 3.0], &[2.0, 2.0]));
    }

    #[test]
    fn crowding_keeps_extremes_and_prefers_sparse_points() {
        let points = p(&[(0.0, 10.0), (1.0, 9.0), (1.2, 8.8), (5.0, 5.0), (10.0, 0.0)]);
        let rank = fronts(&points);
        assert!(rank.iter().all(|&r| r == 0));
        let d = crowding(&points, &rank);
        assert!(d[0].is_infinite() && d[4].is_infinite());
        assert!(d[3] > d[1] && d[3] > d[2], "{d:?}");
        let order = order(&points);
        assert_eq!(&order[..2], &[0, 4]);
        assert_eq!(order[2], 3);
    }

    #[test]
    fn places_invert_the_order() {
        let points = p(&[(3.0, 3.0), (1.0, 1.0), (2.0, 2.0)]);
        assert_eq!(order(&points), vec![1, 2, 0]);
        assert_eq!(places(&points), vec![2, 0, 1]);
    }
}
