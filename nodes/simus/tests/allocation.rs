//! "No allocation per frame once warmed up": a counting global allocator sees no allocation in
//! a second `simulate_into` call with the same plan (the engine reuses its workspaces).
#![allow(clippy::unwrap_used)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use sonoflow_simus::{Accuracy, Medium, Probe, Scatterers, Simus, SimusOptions, Transmit};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn second_frame_does_not_allocate() {
    let probe = Probe::paper_5mhz();
    let medium = Medium::default();
    for accuracy in [Accuracy::default(), Accuracy::Exact] {
        let o = SimusOptions { threads: Some(2), accuracy, ..SimusOptions::default() };
        let mut simus = Simus::new(probe.clone(), medium.clone(), o).unwrap();
        let tx = Transmit::plane_wave(&probe, medium.c, 0.1).unwrap();
        let mut s = Scatterers::default();
        for i in 0..300 {
            s.push((i as f32 * 0.37).sin() * 0.01, 0.01 + (i as f32 * 0.11).cos().abs() * 0.02, 1.0);
        }
        let plan = simus.plan_for_max_distance(0.05, tx.max_delay()).unwrap();
        let mut out = vec![0f32; probe.n_elements * plan.n_samples];
        simus.simulate_into(&s, &tx, &plan, &mut out).unwrap();
        // the scene moves, the plan stays
        for v in s.z.iter_mut() {
            *v += 1e-4;
        }
        let before = ALLOCS.load(Ordering::Relaxed);
        simus.simulate_into(&s, &tx, &plan, &mut out).unwrap();
        let n = ALLOCS.load(Ordering::Relaxed) - before;
        assert_eq!(n, 0, "{n} allocations in a warmed-up frame");
    }
}
