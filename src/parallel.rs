//! Work spread over scoped threads in contiguous shares: the one way
//! filterjit runs a batch in parallel (lowering and validation, pipeline
//! creation, fused-kernel compiles). No dependency is worth it for this.

/// `f` of every item, on up to `threads` threads; results in item order.
pub fn map<T: Sync, R: Send>(items: &[T], threads: usize, f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let chunk = items.len().div_ceil(threads.max(1)).max(1);
    let f = &f;
    std::thread::scope(|s| {
        let handles: Vec<_> =
            items.chunks(chunk).map(|part| s.spawn(move || part.iter().map(f).collect::<Vec<R>>())).collect();
        handles.into_iter().flat_map(|h| h.join().expect("worker thread panicked")).collect()
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn results_come_back_in_order_whatever_the_threads() {
        let items: Vec<u32> = (0..37).collect();
        for threads in [0, 1, 2, 5, 64] {
            assert_eq!(super::map(&items, threads, |x| x * 3), items.iter().map(|x| x * 3).collect::<Vec<_>>());
        }
        assert!(super::map(&[] as &[u32], 4, |x| *x).is_empty());
    }
}
