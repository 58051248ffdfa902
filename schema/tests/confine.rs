//! `Stage::open_within`: a stage may open layers only inside the given
//! directories, whatever the path that names them (relative `..`, absolute,
//! a symlink).

use std::path::{Path, PathBuf};

use curvenet_schema::usd::{Stage, UsdError};

fn fixtures() -> PathBuf {
    std::fs::canonicalize(Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures")).unwrap()
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("curvenet-confine-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    std::fs::canonicalize(d).unwrap()
}

/// The error of an open that must fail.
fn refused(r: Result<Stage, UsdError>) -> UsdError {
    match r {
        Ok(_) => panic!("the stage opened"),
        Err(e) => e,
    }
}

fn forbidden_asset(e: UsdError) -> String {
    match e {
        UsdError::Forbidden { asset, .. } => asset,
        other => panic!("expected Forbidden, got {other}"),
    }
}

#[test]
fn layers_outside_the_roots_are_refused_by_any_path() {
    let shot = fixtures().join("shots/hand_wave/shot.usda");
    // Its sublayers are ./anim.usda and ../../hand/hand_1k4.usda: all inside fixtures/.
    let inside = Stage::open_within(&shot, &[fixtures()]).unwrap();
    assert_eq!(inside.deformed_meshes().unwrap().len(), 1);
    // Confined to the shot's own directory, the relative `..` sublayer is refused.
    let e = refused(Stage::open_within(&shot, &[fixtures().join("shots/hand_wave")]));
    assert!(forbidden_asset(e.clone()).contains("hand_1k4.usda"), "{e}");
    assert!(e.to_string().contains("outside the allowed directories"), "{e}");

    // A stage inside the root that sublayers an absolute path outside it.
    let root = temp_dir("absolute");
    let outside = fixtures().join("hand/hand_1k4.usda");
    std::fs::write(root.join("shot.usda"), format!("#usda 1.0\n(\n    subLayers = [@{}@]\n)\n", outside.display()))
        .unwrap();
    let e = refused(Stage::open_within(root.join("shot.usda"), std::slice::from_ref(&root)));
    assert!(forbidden_asset(e).contains("hand_1k4.usda"));
    // Unconfined, the same stage opens.
    assert_eq!(Stage::open(root.join("shot.usda")).unwrap().deformed_meshes().unwrap().len(), 1);

    // A symlink inside the root pointing outside it.
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(&outside, root.join("link.usda")).unwrap();
        std::fs::write(root.join("via_link.usda"), "#usda 1.0\n(\n    subLayers = [@./link.usda@]\n)\n").unwrap();
        let e = refused(Stage::open_within(root.join("via_link.usda"), std::slice::from_ref(&root)));
        assert!(matches!(e, UsdError::Forbidden { .. }), "{e}");
        // The root layer itself, named through a symlink, is judged by its target.
        let e = refused(Stage::open_within(root.join("link.usda"), std::slice::from_ref(&root)));
        assert!(matches!(e, UsdError::Forbidden { .. }), "{e}");
    }
    std::fs::remove_dir_all(&root).unwrap();
}
