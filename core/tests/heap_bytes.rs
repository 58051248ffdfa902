//! `Binding::heap_bytes` is what a binding really holds: the bytes a
//! counting allocator sees still allocated after the binding is built (its
//! temporaries freed) agree with it. This binary holds a single test so the
//! allocator sees no other thread.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicIsize, Ordering};

use common::*;
use curvenet_core::binding::surface::Surface;
use curvenet_core::binding::{BindOptions, Binding};
use curvenet_core::{Curvenet, CurvenetLayout, SamplingOptions};

struct Counting;

/// Bytes allocated and not yet freed.
static LIVE: AtomicIsize = AtomicIsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LIVE.fetch_add(layout.size() as isize, Ordering::SeqCst);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size() as isize, Ordering::SeqCst);
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LIVE.fetch_add(new_size as isize - layout.size() as isize, Ordering::SeqCst);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn heap_bytes_is_what_the_allocator_holds_for_the_binding() {
    // The hand and a planar grid, at two densities: small and larger bindings.
    let (hand_mesh, hand_pts) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let (plane_mesh, plane_pts) = plane(3.0, 60);
    let hand_bvh = curvenet_core::ClosestPointBvh::new(&hand_mesh, &hand_pts).unwrap();
    let cases = [
        ("hand", &hand_mesh, &hand_pts, surface_grid(&hand_bvh, [-0.05, 0.45, 0.0], 0.03), 5.0),
        ("plane", &plane_mesh, &plane_pts, grid(0.1), 5.0),
        ("plane dense", &plane_mesh, &plane_pts, grid(0.1), 30.0),
    ];
    // The factorisation orders and factors uncoupled blocks on rayon's
    // global pool: start it first, so its own allocations (the worker
    // threads' queues) are not counted as the binding's.
    rayon::join(|| (), || ());
    for (name, mesh, pts, net, density) in cases {
        let c = Curvenet::new(&net.splines, &net.points).unwrap();
        let options = SamplingOptions::default().with_density(density);
        let before = LIVE.load(Ordering::SeqCst);
        let binding = {
            let surface = Surface::new(mesh, pts).unwrap();
            let layout =
                CurvenetLayout::with_closest_point(&c, surface.closest_points(), surface.mean_edge_length(), &options)
                    .unwrap();
            Box::new(Binding::with_surface(surface, &[&layout], &BindOptions::default(), 0.0).unwrap())
        };
        let held = (LIVE.load(Ordering::SeqCst) - before) as usize;
        let measured = binding.heap_bytes() + std::mem::size_of::<Binding>();
        let off = measured.abs_diff(held) as f64 / held as f64;
        println!("{name}: allocator holds {held} bytes, heap_bytes + struct {measured} ({:.2}% off)", off * 100.0);
        // faer's symbolic analysis is counted by its arrays' lengths, not
        // capacities, and a few small allocations (its Arc) are not counted.
        assert!(off < 0.01, "{name}: allocator holds {held} bytes, heap_bytes says {measured}");
        drop(binding);
    }
}
