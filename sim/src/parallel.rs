//! Running two pieces of work side by side on rayon's threads: the one place the mesh update,
//! the cutter's candidate scan and the solver's sweeps and assembly get their second thread
//! from. Each caller splits its work into two halves whose results do not depend on which
//! thread ran them, so results are the same bits on one thread or two.

/// `a` and `b`, on two threads when `parallel` (the same results either way).
pub(crate) fn join<RA: Send, RB: Send>(
    parallel: bool,
    a: impl FnOnce() -> RA + Send,
    b: impl FnOnce() -> RB + Send,
) -> (RA, RB) {
    if parallel {
        side_by_side(a, b)
    } else {
        (a(), b())
    }
}

/// `a` and `b` on two threads. Called from outside rayon's pool (the simulation's own thread),
/// `a` runs on the calling thread while a worker takes `b`, instead of both waiting for
/// workers to wake while the caller sleeps ([`rayon::join`] from outside the pool).
pub(crate) fn side_by_side<RA: Send, RB: Send>(
    a: impl FnOnce() -> RA + Send,
    b: impl FnOnce() -> RB + Send,
) -> (RA, RB) {
    if rayon::current_thread_index().is_some() {
        return rayon::join(a, b);
    }
    let mut rb = None;
    let ra = rayon::in_place_scope(|s| {
        s.spawn(|_| rb = Some(b()));
        a()
    });
    (ra, rb.expect("the scope waits for its spawned job"))
}
