//! Work spread over threads: one shared queue of items (a thread takes the next item not yet
//! taken, so uneven items balance), the results in the items' order. The diagnosis's class fits,
//! the blind test's trials and `ddct sim`'s scenarios run through it.

/// `f(i, item)` for every item on up to `threads` threads; the results in index order. A panic
/// in `f` is raised again here, not turned into a missing result.
pub fn map<T: Sync, R: Send>(
    threads: usize,
    items: &[T],
    f: impl Fn(usize, &T) -> R + Sync,
) -> Vec<R> {
    map_with(threads, items, || (), |_, i, t| f(i, t))
}

/// [`map`] with a state per thread: `init()` once on each thread, then `f(&mut state, i, item)`
/// for the items that thread takes (scratch buffers, caches that are only a matter of speed).
pub(crate) fn map_with<T: Sync, S, R: Send>(
    threads: usize,
    items: &[T],
    init: impl Fn() -> S + Sync,
    f: impl Fn(&mut S, usize, &T) -> R + Sync,
) -> Vec<R> {
    let order: Vec<usize> = (0..items.len()).collect();
    run(threads, items, &order, init, f)
}

/// [`map`] with the items taken from the queue in decreasing `cost` (equal costs in index
/// order): the longest item does not start last and leave the other threads idle while it runs.
/// Only the schedule changes: `f` sees the same `(i, item)` pairs and the results come back in
/// index order.
pub(crate) fn map_costliest_first<T: Sync, R: Send, C: Ord>(
    threads: usize,
    items: &[T],
    cost: impl Fn(&T) -> C,
    f: impl Fn(usize, &T) -> R + Sync,
) -> Vec<R> {
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by(|a, b| cost(&items[*b]).cmp(&cost(&items[*a])).then(a.cmp(b)));
    run(threads, items, &order, || (), |_, i, t| f(i, t))
}

/// The items in the queue order `order` (a permutation of the indices), results by index; each
/// thread's state from `init`.
fn run<T: Sync, S, R: Send>(
    threads: usize,
    items: &[T],
    order: &[usize],
    init: impl Fn() -> S + Sync,
    f: impl Fn(&mut S, usize, &T) -> R + Sync,
) -> Vec<R> {
    let threads = threads.clamp(1, items.len().max(1));
    if threads == 1 {
        // On the calling thread: no thread to start for one.
        let mut state = init();
        let mut done: Vec<(usize, R)> = order
            .iter()
            .map(|&i| (i, f(&mut state, i, &items[i])))
            .collect();
        done.sort_by_key(|(i, _)| *i);
        return done.into_iter().map(|(_, r)| r).collect();
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut done: Vec<(usize, R)> = std::thread::scope(|sc| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                let (next, init, f) = (&next, &init, &f);
                sc.spawn(move || {
                    let (mut mine, mut state) = (Vec::new(), init());
                    loop {
                        let q = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(&i) = order.get(q) else { break };
                        mine.push((i, f(&mut state, i, &items[i])));
                    }
                    mine
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One state per thread, kept across the items the thread takes; the results as `map`'s.
    #[test]
    fn one_state_per_thread() {
        let items: Vec<u64> = (0..40).collect();
        let inits = std::sync::atomic::AtomicUsize::new(0);
        let out = map_with(
            2,
            &items,
            || {
                inits.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                0u64
            },
            |seen, _, &x| {
                *seen += 1;
                (x * 3, *seen)
            },
        );
        assert_eq!(
            out.iter().map(|r| r.0).collect::<Vec<_>>(),
            items.iter().map(|x| x * 3).collect::<Vec<_>>()
        );
        assert!(inits.into_inner() <= 2);
        // Each thread's count runs 1, 2, … over its items: the states were kept. With a and b
        // items on the two threads (a + b = 40), the counts are 1..=a and 1..=b.
        let a = out.iter().map(|r| r.1).max().unwrap();
        let b = 40 - a;
        for v in 1..=a {
            let n = out.iter().filter(|r| r.1 == v).count();
            assert_eq!(n, 1 + usize::from(v <= b), "count {v}");
        }
    }

    /// Every item once, in order, whatever the thread count and however uneven the items.
    #[test]
    fn every_item_once_in_order() {
        let items: Vec<u64> = (0..57).collect();
        for threads in [0, 1, 2, 7, 100] {
            let out = map(threads, &items, |i, &x| {
                // Uneven work: some items take much longer.
                if x % 5 == 0 {
                    std::thread::sleep(std::time::Duration::from_millis(2));
                }
                (i, x * x)
            });
            assert_eq!(out.len(), items.len());
            for (k, (i, sq)) in out.iter().enumerate() {
                assert_eq!((*i, *sq), (k, items[k] * items[k]));
            }
        }
        assert!(map(2, &[] as &[u8], |_, _| 1).is_empty());
    }

    /// The costliest item is taken first (one thread: the order `f` is called in), and the
    /// results still come back by index, each with its own index.
    #[test]
    fn costliest_first_changes_the_schedule_not_the_results() {
        let items = [3u32, 9, 1, 9, 5];
        let seen = std::sync::Mutex::new(Vec::new());
        let out = map_costliest_first(
            1,
            &items,
            |x| *x,
            |i, x| {
                seen.lock().unwrap().push(i);
                (i, x * 10)
            },
        );
        assert_eq!(*seen.lock().unwrap(), vec![1, 3, 4, 0, 2]);
        assert_eq!(out, vec![(0, 30), (1, 90), (2, 10), (3, 90), (4, 50)]);
        for threads in [2, 3, 8] {
            let again = map_costliest_first(threads, &items, |x| *x, |i, x| (i, x * 10));
            assert_eq!(again, out);
        }
    }
}
