//! `curvenet draft INPUT --out OUT.usda [--mesh PRIM] [--rings N] [--lines M]
//! [--offset F] [--axis X,Y,Z] [--across X,Y,Z] [--span A,B] [--seed S] [--json]`:
//! drafts a starting curvenet on a stage's mesh from plane sections
//! (`curvenet_core::draft`: rings around the main axis, lengthwise lines
//! between the first and last ring, knots shared at their crossings) and
//! writes it as a layer that sublayers INPUT and binds the curvenet to the
//! mesh (`curvenet_schema::usd::write_curvenet_layer`), or prints it as JSON.

use std::path::{Component, Path, PathBuf};

use curvenet_core::PolyMesh;
use curvenet_core::{Draft, DraftError, DraftOptions, Jitter, draft};
use curvenet_schema::usd::{CurvenetLayer, Stage, WriteError, write_curvenet_layer};
use serde::Serialize;

use super::units::parse_numbers;
use super::{CliError, CliResult, check_output_dir};

const AFTER_HELP: &str = "\
The curvenet: rings are the sections of the mesh (its projection pose) by N
planes perpendicular to the axis, spread over --span (fractions of the mesh's
extent along the axis); lines are the sections by M parallel planes that contain
the axis, clipped between the first and last ring, so they end in T-junctions
on the end rings and cross the inner rings at shared knots. Splines are fitted
to the sections and pushed --offset (a fraction of the bounding-box diagonal)
off the surface along its normal, less where a concavity or a nearby part of the
mesh is closer than that. Plane positions that would give grazing crossings or
knots closer than a mean edge are moved; the command fails (exit 2) naming the
ring or line when no position works. The same input and options give the same
curvenet; --seed S adds a seeded random jitter (plane positions and tilts, the
lines' direction, knot offsets and handles) for a different draft.

Output (--out): a layer that sublayers INPUT (by a path relative to the layer's
directory, absolute when the two share only the root directory),
defines the curvenet as a BasisCurves prim next to the mesh (named Curvenet, or
Curvenet1, Curvenet2, ... when taken) following the curvenet contract
(schema/README.md), and binds it with an `over` of the mesh authoring
`rel curvenet:curvenets` (replacing the curvenets the mesh had). Open it in
place of INPUT, or sublayer it above INPUT. --json prints one JSON document
(`pool`, `splines`, the options and a report) to stdout.

Exit status: 0 success; 2 bad input (no or several meshes without --mesh, a
mesh the contract refuses, bad options, no clean curvenet); 75 an I/O failure
writing OUT (including a missing output directory, checked first).";

#[derive(clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// The stage holding the mesh (.usda, .usdc, .usdz).
    pub input: PathBuf,
    /// The layer to write: .usda (text) or .usdc (binary), by its extension.
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// The mesh prim to draft on (default: the stage's only Mesh).
    #[arg(long)]
    pub mesh: Option<String>,
    /// Number of rings (planes across the axis).
    #[arg(long, default_value_t = 5)]
    pub rings: usize,
    /// Number of lengthwise lines (parallel planes containing the axis); 0 for rings only.
    #[arg(long, default_value_t = 4)]
    pub lines: usize,
    /// Distance off the surface, as a fraction of the bounding-box diagonal.
    #[arg(long, default_value_t = 0.005)]
    pub offset: f64,
    /// The main axis (default: the principal axis of the area-weighted vertices).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vector, allow_hyphen_values = true)]
    pub axis: Option<[f64; 3]>,
    /// Normal of the lengthwise planes (default: the principal direction across the axis).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vector, allow_hyphen_values = true)]
    pub across: Option<[f64; 3]>,
    /// First and last ring as fractions of the extent along the axis.
    #[arg(long, value_name = "A,B", value_parser = parse_span, default_value = "0.1,0.9")]
    pub span: [f64; 2],
    /// Add a seeded random jitter to the draft (see below).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Print the curvenet as one JSON document on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn parse_vector(s: &str) -> Result<[f64; 3], String> {
    parse_numbers(s, "three numbers X,Y,Z")
}

pub fn parse_span(s: &str) -> Result<[f64; 2], String> {
    parse_numbers(s, "two fractions A,B")
}

#[derive(Serialize)]
struct JsonOut<'a> {
    stage: String,
    mesh: &'a str,
    curvenet: &'a str,
    pool: &'a [[f64; 3]],
    splines: &'a [[u32; 4]],
    options: JsonOptions,
    report: JsonReport,
}

#[derive(Serialize)]
struct JsonOptions {
    rings: usize,
    lines: usize,
    span: [f64; 2],
    offset: f64,
    axis: Option<[f64; 3]>,
    across: Option<[f64; 3]>,
    seed: Option<u64>,
}

#[derive(Serialize)]
struct JsonReport {
    axis: [f64; 3],
    across: [f64; 3],
    centroid: [f64; 3],
    rings: Vec<JsonRing>,
    lines: Vec<JsonLine>,
    knots: usize,
    anchors: usize,
    t_junctions: usize,
    intersections: usize,
    isolated_loops: usize,
    splines: usize,
    offset: f64,
    reduced_pushes: usize,
    max_fit_error: f64,
    attempts: usize,
    mean_edge_length: f64,
    diagonal: f64,
}

#[derive(Serialize)]
struct JsonRing {
    normal: [f64; 3],
    point: [f64; 3],
    centre: [f64; 3],
    position: f64,
    loops: usize,
}

#[derive(Serialize)]
struct JsonLine {
    normal: [f64; 3],
    offset: f64,
}

fn json_report(d: &Draft) -> JsonReport {
    let r = &d.report;
    JsonReport {
        axis: r.axis,
        across: r.across,
        centroid: r.centroid,
        rings: r
            .rings
            .iter()
            .map(|g| JsonRing {
                normal: g.normal,
                point: g.point,
                centre: g.centre,
                position: g.position,
                loops: g.loops,
            })
            .collect(),
        lines: r.lines.iter().map(|l| JsonLine { normal: l.normal, offset: l.offset }).collect(),
        knots: r.knots,
        anchors: r.anchors,
        t_junctions: r.t_junctions,
        intersections: r.intersections,
        isolated_loops: r.isolated_loops,
        splines: r.splines,
        offset: r.offset,
        reduced_pushes: r.reduced_pushes,
        max_fit_error: r.max_fit_error,
        attempts: r.attempts,
        mean_edge_length: r.mean_edge_length,
        diagonal: r.diagonal,
    }
}

pub fn run(args: &Args) -> CliResult {
    if args.out.is_none() && !args.json {
        return Err(CliError::Input("nothing to do: give --out OUT.usda (or .usdc) and/or --json".into()));
    }
    if let Some(out) = &args.out {
        curvenet_schema::usd::LayerFormat::from_path(out).map_err(|e| CliError::Input(e.to_string()))?;
        check_output_dir(out)?;
        if same_file(out, &args.input) {
            return Err(CliError::Input(format!("{}: the output must not be the input", out.display())));
        }
    }
    let stage = Stage::open(&args.input)?;
    let mesh_path = match &args.mesh {
        Some(p) => p.clone(),
        None => {
            let meshes = stage.mesh_paths()?;
            match meshes.as_slice() {
                [one] => one.clone(),
                [] => return Err(CliError::Input(format!("{}: the stage has no Mesh prim", stage.path()))),
                many => {
                    return Err(CliError::Input(format!(
                        "{}: the stage has {} meshes ({}); choose one with --mesh",
                        stage.path(),
                        many.len(),
                        many.join(", ")
                    )));
                }
            }
        }
    };
    let mesh = stage.mesh(&mesh_path)?;
    let core = |source| CliError::Core { context: mesh.path.clone(), source };
    let topology = PolyMesh::new(&mesh.face_vertex_counts, &mesh.face_vertex_indices, mesh.projection_points.len())
        .map_err(core)?;
    let mut options = DraftOptions::default()
        .with_rings(args.rings)
        .with_lines(args.lines)
        .with_span(args.span)
        .with_offset(args.offset)
        .with_jitter(args.seed.map(Jitter::new));
    if let Some(a) = args.axis {
        options = options.with_axis(a);
    }
    if let Some(b) = args.across {
        options = options.with_across(b);
    }
    let drafted = draft(&topology, &mesh.projection_points, &options).map_err(|e| match e {
        DraftError::Mesh(source) => CliError::Core { context: mesh.path.clone(), source },
        e => CliError::Input(format!("{}: {e}", mesh.path)),
    })?;
    let curvenet_path = free_sibling(&stage, &mesh.path, "Curvenet");

    if let Some(out) = &args.out {
        let layer = CurvenetLayer {
            sublayer: relative_asset_path(out, &args.input),
            mesh: mesh.path.clone(),
            curvenet: curvenet_path.clone(),
            pool: drafted.pool.iter().map(|p| p.map(|x| x as f32)).collect(),
            splines: drafted.splines.clone(),
            sample_density: curvenet_schema::wire::DEFAULT_SAMPLE_DENSITY as f32,
            doc: layer_doc(args, &mesh.path),
        };
        write_curvenet_layer(out, &layer).map_err(write_error)?;
    }
    if args.json {
        let doc = JsonOut {
            stage: args.input.display().to_string(),
            mesh: &mesh.path,
            curvenet: &curvenet_path,
            pool: &drafted.pool,
            splines: &drafted.splines,
            options: JsonOptions {
                rings: args.rings,
                lines: args.lines,
                span: args.span,
                offset: args.offset,
                axis: args.axis,
                across: args.across,
                seed: args.seed,
            },
            report: json_report(&drafted),
        };
        let text = serde_json::to_string(&doc).map_err(|e| CliError::Input(format!("cannot encode JSON: {e}")))?;
        println!("{text}");
    } else {
        let r = &drafted.report;
        println!(
            "drafted {curvenet_path} on {}: {} control points, {} splines, {} knots ({} intersections, {} T-junctions, \
             {} free ends), {} isolated loops; {} rings, {} lines, offset {:.4} ({:.2} % of the diagonal, {} section points pushed less)",
            mesh.path,
            drafted.pool.len(),
            r.splines,
            r.knots,
            r.intersections,
            r.t_junctions,
            r.anchors,
            r.isolated_loops,
            r.rings.len(),
            r.lines.len(),
            r.offset,
            100.0 * args.offset,
            r.reduced_pushes,
        );
        if let Some(out) = &args.out {
            println!("wrote {}", out.display());
        }
    }
    Ok(())
}

fn write_error(e: WriteError) -> CliError {
    match e {
        WriteError::Io { what, path, source } => CliError::Io { context: format!("{what} {path}"), source },
        e => CliError::Input(e.to_string()),
    }
}

/// The layer's doc: what drafted it, on what, with which options (no time
/// stamp, so the same draft writes the same bytes).
fn layer_doc(args: &Args, mesh: &str) -> String {
    let vector = |v: Option<[f64; 3]>, default: &str| {
        v.map(|v| format!("({}, {}, {})", v[0], v[1], v[2])).unwrap_or_else(|| default.into())
    };
    format!(
        "Curvenet drafted by curvenet {} (curvenet draft) on {mesh} of {}: {} rings from {} to {} of the extent along \
         {}, {} lines across {}, offset {} of the diagonal{}.",
        env!("CARGO_PKG_VERSION"),
        args.input.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
        args.rings,
        args.span[0],
        args.span[1],
        vector(args.axis, "the principal axis"),
        args.lines,
        vector(args.across, "the principal direction"),
        args.offset,
        args.seed.map(|s| format!(", jitter seed {s}")).unwrap_or_default(),
    )
}

/// `<parent of prim>/<name>`, or `<name>1`, `<name>2`, ... when taken.
fn free_sibling(stage: &Stage, prim: &str, name: &str) -> String {
    let parent = match prim.rfind('/') {
        Some(0) | None => "",
        Some(i) => &prim[..i],
    };
    (0..)
        .map(|n| if n == 0 { format!("{parent}/{name}") } else { format!("{parent}/{name}{n}") })
        .find(|p| !stage.has_prim(p))
        .expect("some name is free")
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// `input` as seen from the directory of `layer`: a relative path when both
/// resolve and share more than the root (with `/` separators), else `input`
/// made absolute.
fn relative_asset_path(layer: &Path, input: &Path) -> String {
    let absolute = |p: &Path| std::path::absolute(p).ok();
    let dir = layer.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let (Some(dir), Some(target)) =
        (std::fs::canonicalize(dir).ok(), std::fs::canonicalize(input).ok().or(absolute(input)))
    else {
        return input.display().to_string();
    };
    let from: Vec<Component> = dir.components().collect();
    let to: Vec<Component> = target.components().collect();
    let common = from.iter().zip(&to).take_while(|(a, b)| a == b).count();
    // Sharing only the root (or nothing): the absolute path reads better.
    if common <= 1 {
        return target.display().to_string();
    }
    let mut parts: Vec<String> = vec!["..".into(); from.len() - common];
    parts.extend(to[common..].iter().map(|c| c.as_os_str().to_string_lossy().into_owned()));
    let rel = parts.join("/");
    if rel.starts_with("..") { rel } else { format!("./{rel}") }
}
