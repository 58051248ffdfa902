//! Cooperative cancellation of a binding (`BindOptions::with_cancel`): a
//! raised flag stops the binding at its next check with `Error::Cancelled`,
//! and an unraised one changes nothing.

mod common;

use std::time::{Duration, Instant};

use common::*;
use curvenet_core::binding::{BindOptions, Binding};
use curvenet_core::{Cancel, Curvenet, CurvenetLayout, Error, PolyMesh, SamplingOptions};

/// The grid curvenet over a 120 × 120 plane, sampled densely enough that the
/// binding takes a while (tens of milliseconds or more).
fn setup() -> (PolyMesh, Vec<[f64; 3]>, CurvenetLayout) {
    let (mesh, pts) = plane(3.0, 120);
    let net = grid(0.1);
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    let layout = CurvenetLayout::new(&c, &mesh, &pts, &SamplingOptions::default().with_density(40.0)).unwrap();
    (mesh, pts, layout)
}

#[test]
fn a_raised_flag_stops_the_binding_before_any_work() {
    let (mesh, pts, layout) = setup();
    let cancel = Cancel::new();
    cancel.cancel();
    let t = Instant::now();
    let e = Binding::new(&mesh, &pts, &[&layout], &BindOptions::default().with_cancel(cancel)).unwrap_err();
    assert!(matches!(e, Error::Cancelled { stage: "the surface" }), "{e:?}");
    assert!(t.elapsed() < Duration::from_millis(50), "{:?}", t.elapsed());
    assert_eq!(e.to_string(), "cancelled during the surface");
}

#[test]
fn a_flag_raised_mid_binding_stops_it_early_and_an_unraised_one_changes_nothing() {
    let (mesh, pts, layout) = setup();
    let t = Instant::now();
    let whole = Binding::new(&mesh, &pts, &[&layout], &BindOptions::default().with_cancel(Cancel::new())).unwrap();
    let full = t.elapsed();
    let plain = Binding::new(&mesh, &pts, &[&layout], &BindOptions::default()).unwrap();
    assert_eq!(format!("{:?}", whole.stats()), format!("{:?}", plain.stats()));

    // Raised a tenth of the way in: the binding stops at a check well before the end.
    let cancel = Cancel::new();
    let raiser = {
        let cancel = cancel.clone();
        std::thread::spawn(move || {
            std::thread::sleep(full / 10);
            cancel.cancel();
        })
    };
    let t = Instant::now();
    let r = Binding::new(&mesh, &pts, &[&layout], &BindOptions::default().with_cancel(cancel.clone()));
    let took = t.elapsed();
    raiser.join().unwrap();
    assert!(cancel.is_cancelled());
    match r {
        Err(Error::Cancelled { stage }) => {
            assert!(["cutting", "assembly", "the factorisation"].contains(&stage), "{stage}");
        }
        other => panic!("expected Cancelled, got {:?}", other.map(|b| b.stats())),
    }
    // Err(Cancelled) itself shows the binding did not run to its end (its
    // last check follows the factorisation); the times are for the log.
    println!("whole binding {full:?}, cancelled at {:?} and stopped after {took:?}", full / 10);
}
