//! `curvenet serve`: the HTTP service (`curvenet_server`, server/src/service/).
//! Every flag also reads an environment variable (`CURVENET_ADDR`,
//! `CURVENET_CACHE_BYTES`, ...); flags win. The bound address is printed on
//! stdout at startup (`listening on http://ADDR`), logs go to stderr
//! (`CURVENET_LOG` / `RUST_LOG` filter, default `info`).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use clap::Parser as _;
use curvenet_schema::usd::{BlendShapeOrder, CurvenetSkinning, Stage};
use curvenet_schema::wire::{AdjustmentSpec, BindingRequest, BlendShapeMode, CurvenetSkinSpec, FrameRequest};
use curvenet_schema::{AdjustmentData, CurvenetData, MeshData};
use curvenet_server::{
    AppState, BakeFailure, BakeJob, Baker, Config, Drained, FrameSource, StageAdjustment, ViewerStage,
};

use super::bake::FrameReading;
use super::{CliError, CliResult};

#[derive(clap::Args)]
pub struct Args {
    /// Address to listen on (port 0: any free port; the bound address is printed).
    #[arg(long, env = "CURVENET_ADDR", default_value = "127.0.0.1:8720")]
    pub addr: String,
    /// Memory for cached bindings (estimated), e.g. 2GiB, 512MiB, 1000000.
    #[arg(long, env = "CURVENET_CACHE_BYTES", default_value = "2GiB", value_parser = super::units::parse_bytes)]
    pub cache_bytes: u64,
    /// Largest request body, e.g. 256MiB.
    #[arg(long, env = "CURVENET_BODY_LIMIT", default_value = "256MiB", value_parser = super::units::parse_bytes)]
    pub body_limit: u64,
    /// Solves (frames, bindings, bakes) admitted at once, running or queued
    /// for a solve thread; beyond it: 503 with Retry-After.
    #[arg(long, env = "CURVENET_MAX_SOLVES", default_value_t = curvenet_server::DEFAULT_MAX_SOLVES)]
    pub max_solves: usize,
    /// Threads solving frames (0: one per core).
    #[arg(long, env = "CURVENET_SOLVE_THREADS", default_value_t = 0)]
    pub solve_threads: usize,
    /// Seconds requests in flight may finish after SIGTERM/SIGINT; then
    /// what still runs is cancelled and the process exits with status 1.
    #[arg(long, env = "CURVENET_DRAIN_TIMEOUT", default_value_t = 30.0)]
    pub drain_timeout: f64,
    /// Largest sample_density of a curvenet (samples per mean edge length).
    #[arg(long, env = "CURVENET_MAX_SAMPLE_DENSITY", default_value_t = curvenet_server::DEFAULT_MAX_SAMPLE_DENSITY)]
    pub max_sample_density: f64,
    /// Largest number of curvenet segments of a binding per mesh vertex
    /// (never fewer than 20000 in all).
    #[arg(long, env = "CURVENET_MAX_SEGMENTS_PER_VERTEX", default_value_t = curvenet_server::DEFAULT_MAX_SEGMENTS_PER_VERTEX)]
    pub max_segments_per_vertex: f64,
    /// Seconds a binding may compute before it is cancelled (422 limit_exceeded).
    #[arg(long, env = "CURVENET_MAX_BINDING_SECONDS", default_value_t = 120.0)]
    pub max_binding_seconds: f64,
    /// Largest answer of a frames:batch request (frames × vertices × 12
    /// bytes, 48 with gradients), e.g. 256MiB.
    #[arg(long, env = "CURVENET_MAX_BATCH_BYTES", default_value = "256MiB", value_parser = super::units::parse_bytes)]
    pub max_batch_bytes: u64,
    /// Memory all frames:batch requests in flight may hold together (their
    /// frames, results and answers), e.g. 1536MiB; a batch waits in line
    /// for its share up to --queue-timeout (then 503 saturated), and one
    /// larger than all of it is refused (422 limit_exceeded).
    #[arg(long, env = "CURVENET_MAX_BATCH_MEMORY", default_value = "1536MiB", value_parser = super::units::parse_bytes)]
    pub max_batch_memory: u64,
    /// Largest `POST /v1/bake`, as the points it holds until it writes its
    /// layer (frames × vertices × 12 bytes), e.g. 1GiB; over it: 422
    /// limit_exceeded before any work.
    #[arg(long, env = "CURVENET_MAX_BAKE_BYTES", default_value = "1GiB", value_parser = super::units::parse_bytes)]
    pub max_bake_bytes: u64,
    /// Seconds a request waits in line for a solve permit when all are taken (then 503).
    #[arg(long, env = "CURVENET_QUEUE_TIMEOUT", default_value_t = 2.0)]
    pub queue_timeout: f64,
    /// Seconds a client has to send a request's headers once it started.
    #[arg(long, env = "CURVENET_HEADER_TIMEOUT", default_value_t = 10.0)]
    pub header_timeout: f64,
    /// Seconds an idle connection (no request, no byte moving) stays open.
    #[arg(long, env = "CURVENET_IDLE_TIMEOUT", default_value_t = 60.0)]
    pub idle_timeout: f64,
    /// Seconds a request body may stall; after as long, it must also have
    /// arrived at --body-min-rate on average (408 and the connection closed).
    #[arg(long, env = "CURVENET_BODY_TIMEOUT", default_value_t = 30.0)]
    pub body_timeout: f64,
    /// Slowest average request-body rate accepted after --body-timeout, e.g. 16KiB (per second).
    #[arg(long, env = "CURVENET_BODY_MIN_RATE", default_value = "16KiB", value_parser = super::units::parse_bytes)]
    pub body_min_rate: u64,
    /// Connections open at once; beyond, a client gets 503 and is disconnected.
    #[arg(long, env = "CURVENET_MAX_CONNECTIONS", default_value_t = curvenet_server::DEFAULT_MAX_CONNECTIONS)]
    pub max_connections: usize,
    /// Require `Authorization: Bearer TOKEN` on every route but /healthz and
    /// /readyz. Prefer the environment variable (a flag shows in `ps`).
    #[arg(long, env = "CURVENET_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// A directory `POST /v1/bake` may read stages from and write layers to
    /// (repeatable; the variable is a comma-separated list). None: baking is refused.
    #[arg(long = "bake-root", env = "CURVENET_BAKE_ROOTS", value_delimiter = ',')]
    pub bake_roots: Vec<PathBuf>,
    /// Instead of serving: GET /healthz on --addr and exit 0 when it answers
    /// 200, 1 otherwise (a container HEALTHCHECK without curl).
    #[arg(long)]
    pub healthcheck: bool,
    /// Open a stage in the viewer (repeatable): each curvenet-deformed mesh
    /// is listed at /viewer, bound on first view, its frames read from the
    /// stage on demand.
    #[arg(long = "open-stage", value_name = "STAGE")]
    pub open_stages: Vec<PathBuf>,
    /// A binding store shared with other replicas and restarts: a directory
    /// (local or NFS) or `s3://bucket/prefix` (credentials and endpoint from
    /// the AWS_* environment). Bindings missing from memory are read from
    /// it before they are built; bindings built here are written to it.
    #[arg(long, env = "CURVENET_STORE", value_name = "DIR|URL")]
    pub store: Option<String>,
    /// Largest size of the store; beyond it the least recently used
    /// bindings are deleted after a write (default: unbounded).
    #[arg(long, env = "CURVENET_STORE_BYTES", value_parser = super::units::parse_bytes, requires = "store")]
    pub store_bytes: Option<u64>,
}

pub fn run(args: &Args) -> CliResult {
    if args.healthcheck {
        healthcheck(&args.addr);
    }
    let seconds = |flag: &str, x: f64, zero_ok: bool| {
        if x.is_finite() && (x > 0.0 || (zero_ok && x == 0.0)) && x <= 1e6 {
            Ok(Duration::from_secs_f64(x))
        } else {
            let what = if zero_ok { "a non-negative" } else { "a positive" };
            Err(CliError::Input(format!("{flag} must be {what} number of seconds (at most 1e6), got {x}")))
        }
    };
    let drain_timeout = seconds("--drain-timeout", args.drain_timeout, true)?;
    let queue_timeout = seconds("--queue-timeout", args.queue_timeout, true)?;
    let max_binding_time = seconds("--max-binding-seconds", args.max_binding_seconds, false)?;
    let header_timeout = seconds("--header-timeout", args.header_timeout, false)?;
    let idle_timeout = seconds("--idle-timeout", args.idle_timeout, false)?;
    let body_timeout = seconds("--body-timeout", args.body_timeout, false)?;
    for (flag, x) in
        [("--max-sample-density", args.max_sample_density), ("--max-segments-per-vertex", args.max_segments_per_vertex)]
    {
        if !(x.is_finite() && x > 0.0) {
            return Err(CliError::Input(format!("{flag} must be a positive number, got {x}")));
        }
    }
    // A zero limit would refuse every request while the server looks healthy.
    for (flag, x) in [
        ("--max-solves", args.max_solves as u64),
        ("--cache-bytes", args.cache_bytes),
        ("--max-connections", args.max_connections as u64),
        ("--body-limit", args.body_limit),
        ("--max-batch-bytes", args.max_batch_bytes),
        ("--max-batch-memory", args.max_batch_memory),
        ("--max-bake-bytes", args.max_bake_bytes),
    ] {
        if x == 0 {
            return Err(CliError::Input(format!("{flag} must be positive: 0 would refuse every request")));
        }
    }
    super::check_threads("--solve-threads", args.solve_threads)?;
    let filter = std::env::var("CURVENET_LOG").or_else(|_| std::env::var("RUST_LOG")).unwrap_or_else(|_| "info".into());
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new(filter))
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
    let config = Config {
        cache_bytes: args.cache_bytes,
        body_limit: usize::try_from(args.body_limit).unwrap_or(usize::MAX),
        max_solves: args.max_solves,
        solve_threads: args.solve_threads,
        drain_timeout,
        token: args.token.clone().filter(|t| !t.is_empty()),
        bake_roots: args.bake_roots.clone(),
        work: curvenet_server::WorkLimits {
            max_sample_density: args.max_sample_density,
            max_segments_per_vertex: args.max_segments_per_vertex,
            max_binding_time,
        },
        queue_timeout,
        max_batch_bytes: args.max_batch_bytes,
        max_batch_memory: args.max_batch_memory,
        max_bake_bytes: args.max_bake_bytes,
        connections: curvenet_server::ConnectionLimits {
            header_timeout,
            idle_timeout,
            body_timeout,
            body_min_rate: args.body_min_rate,
            max_connections: args.max_connections.max(1),
        },
    };
    if args.store_bytes == Some(0) {
        return Err(CliError::Input("--store-bytes must be positive: 0 would delete every binding written".into()));
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("curvenet-http")
        .build()
        .map_err(|e| CliError::Io { context: "starting the runtime".into(), source: e })?;
    let state = match &args.store {
        None => AppState::new(config, Some(baker())),
        Some(location) => runtime.block_on(AppState::open(config, Some(baker()), location, args.store_bytes)),
    }
    .map_err(|e| {
        let store = e.get_ref().and_then(|inner| inner.downcast_ref::<curvenet_server::store::StoreError>());
        match store {
            // A store that is down or unwritable may come back: a supervisor retries on 75.
            Some(s) if !s.is_config() => CliError::Unavailable(e.to_string()),
            _ => CliError::Input(e.to_string()),
        }
    })?;
    for path in &args.open_stages {
        for stage in open_stage(path)? {
            state.open_in_viewer(stage);
        }
    }
    let drained = runtime.block_on(async {
        // Listen for the signals before announcing the address: a SIGTERM
        // right after startup must stop the server, not kill the process.
        let shutdown =
            shutdown_signal().map_err(|e| CliError::Io { context: "installing signal handlers".into(), source: e })?;
        let listener = tokio::net::TcpListener::bind(&args.addr)
            .await
            .map_err(|e| CliError::Io { context: format!("binding {}", args.addr), source: e })?;
        let addr = listener
            .local_addr()
            .map_err(|e| CliError::Io { context: "reading the bound address".into(), source: e })?;
        println!("listening on http://{addr}");
        if !args.open_stages.is_empty() {
            println!("viewer: http://{addr}/viewer");
        }
        use std::io::Write as _;
        let _ = std::io::stdout().flush();
        let config = state.config();
        tracing::info!(
            %addr,
            auth = config.token.is_some(),
            cache_bytes = config.cache_bytes,
            max_solves = config.max_solves,
            max_batch_bytes = config.max_batch_bytes,
            max_batch_memory = config.max_batch_memory,
            store = args.store.as_deref().unwrap_or("none"),
            "curvenet serve"
        );
        curvenet_server::run(listener, state, shutdown)
            .await
            .map_err(|e| CliError::Io { context: format!("serving on {addr}"), source: e })
    })?;
    // Work still running (a cancelled binding finishing its factorisation, a
    // bake) must not keep the process alive past the drain deadline.
    runtime.shutdown_timeout(Duration::from_millis(200));
    match drained {
        Drained::Clean => {
            tracing::info!("stopped");
            Ok(())
        }
        Drained::CutShort { connections, bindings } => {
            tracing::warn!(connections, bindings, "stopped with requests cut short at the drain timeout");
            Err(CliError::CutShort(format!(
                "the drain timeout ({:.1} s) passed with {connections} connections still busy; {bindings} bindings cancelled",
                drain_timeout.as_secs_f64()
            )))
        }
    }
}

/// A future resolving on SIGINT (Ctrl-C) or SIGTERM (docker stop,
/// Kubernetes); the handlers are installed when this is called.
fn shutdown_signal() -> std::io::Result<impl std::future::Future<Output = ()> + Send + 'static> {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        let mut term = signal(SignalKind::terminate())?;
        let mut int = signal(SignalKind::interrupt())?;
        Ok(async move {
            tokio::select! {
                _ = term.recv() => {},
                _ = int.recv() => {},
            }
        })
    }
    #[cfg(not(unix))]
    {
        Ok(async {
            let _ = tokio::signal::ctrl_c().await;
        })
    }
}

/// `serve --healthcheck`: exits 0 when GET /healthz answers 200, else 1
/// (Docker reserves exit status 2, the command line's bad-input status).
fn healthcheck(addr: &str) -> ! {
    use std::io::{Read as _, Write as _};
    let target: Option<SocketAddr> = addr.parse::<SocketAddr>().ok().map(|mut a| {
        if a.ip().is_unspecified() {
            a.set_ip(if a.is_ipv4() { [127, 0, 0, 1].into() } else { std::net::Ipv6Addr::LOCALHOST.into() });
        }
        a
    });
    let ok = target.is_some_and(|a| {
        let Ok(mut s) = std::net::TcpStream::connect_timeout(&a, Duration::from_secs(3)) else { return false };
        let _ = s.set_read_timeout(Some(Duration::from_secs(3)));
        let request = format!("GET /healthz HTTP/1.1\r\nHost: {a}\r\nConnection: close\r\n\r\n");
        let mut answer = String::new();
        s.write_all(request.as_bytes()).is_ok()
            && s.read_to_string(&mut answer).is_ok()
            && answer.starts_with("HTTP/1.1 200")
    });
    if !ok {
        eprintln!("curvenet: healthcheck: http://{addr}/healthz did not answer 200");
    }
    std::process::exit(if ok { 0 } else { 1 })
}

/// The bake behind `POST /v1/bake`: the `curvenet bake` command itself,
/// given the checked paths as its arguments.
fn baker() -> Baker {
    #[derive(clap::Parser)]
    struct Bake {
        #[command(flatten)]
        args: super::bake::Args,
    }
    Arc::new(|job: &BakeJob| {
        let mut argv = vec![
            "bake".into(),
            job.stage.clone().into_os_string(),
            "--out".into(),
            job.output.clone().into_os_string(),
        ];
        if let Some(f) = &job.frames {
            // Checked here so the answer names the field, not a command-line flag.
            super::bake::parse_frames(f)
                .map_err(|m| BakeFailure::Input(format!("frames {}: {m}", super::bake::quoted(f))))?;
            argv.push("--frames".into());
            argv.push(f.into());
        }
        for root in &job.roots {
            argv.push("--confine".into());
            argv.push(root.clone().into_os_string());
        }
        argv.push("--quiet".into());
        let bake = Bake::try_parse_from(argv).map_err(|e| {
            // Not reachable with checked paths and frames; no command-line hints in an HTTP answer.
            let text = e.to_string();
            let first = text.lines().next().unwrap_or_default().trim_start_matches("error: ");
            BakeFailure::Input(first.to_string())
        })?;
        // The warnings go back in the answer, not to the server's stderr.
        let mut warnings = Vec::new();
        let bounds =
            super::bake::Bounds { max_points_bytes: Some(job.max_points_bytes), cancel: Some(job.cancel.clone()) };
        super::bake::run_with(&bake.args, &mut |w| warnings.push(w), &bounds).map_err(|e| match e {
            CliError::Usd(curvenet_schema::usd::UsdError::Forbidden { .. }) => BakeFailure::Forbidden(e.to_string()),
            CliError::Limit(m) => BakeFailure::Limit(m),
            CliError::Cancelled => BakeFailure::Cancelled,
            e if e.exit_code() == 75 => BakeFailure::Retry(e.to_string()),
            e => BakeFailure::Input(e.to_string()),
        })?;
        Ok(warnings)
    })
}

/// A frame request to the thread that owns an opened stage: (mesh, frame,
/// where to answer).
type FrameQuery = (usize, usize, std::sync::mpsc::Sender<Result<FrameRequest, String>>);

/// Opens `path` for the viewer: one [`ViewerStage`] per curvenet-deformed
/// mesh, with the frames `curvenet bake` would bake (a stage with no time
/// range and no time samples has one frame, its default values) and, as the
/// bake reads them, each curvenet's `CurvenetAdjustment` prims, applied to
/// every frame. The USD stage is not `Send`, so one thread owns it and reads
/// frames on request. Fails, naming the stage and prim, when the stage
/// breaks the contract.
pub fn open_stage(path: &std::path::Path) -> CliResult<Vec<ViewerStage>> {
    type Opened =
        (Vec<(MeshData, Vec<CurvenetData>, bool)>, Vec<f64>, String, Vec<Vec<StageAdjustment>>, Vec<Underneath>);
    let (setup_tx, setup_rx) = std::sync::mpsc::channel::<CliResult<Opened>>();
    let (query_tx, query_rx) = std::sync::mpsc::channel::<FrameQuery>();
    let owned = path.to_path_buf();
    std::thread::Builder::new()
        .name("curvenet-stage-reader".into())
        .spawn(move || {
            let opened = (|| -> CliResult<(Stage, Vec<FrameReading>, Opened)> {
                let stage = Stage::open(&owned)?;
                let inputs = super::deformed_meshes(&stage, "view")?;
                let animated = stage.time_code_range().is_some()
                    || inputs.iter().any(|(m, nets, _)| {
                        !m.rest_sample_times.is_empty() || nets.iter().any(|n| !n.sample_times.is_empty())
                    });
                let times = if animated { super::bake::frames(&stage, None, &inputs, &mut |_| {})? } else { vec![0.0] };
                let name = stage.path().to_string();
                let adjustments =
                    inputs.iter().map(|(_, nets, _)| stage_adjustments(&stage, nets)).collect::<CliResult<Vec<_>>>()?;
                let underneath = inputs
                    .iter()
                    .map(|(m, nets, _)| Underneath::read(&stage, m, nets))
                    .collect::<CliResult<Vec<_>>>()?;
                let readings = inputs
                    .iter()
                    .zip(&underneath)
                    .map(|((m, _, r), u)| FrameReading::new(&stage, m, *r, u.skin.is_some()))
                    .collect::<CliResult<Vec<_>>>()?;
                Ok((stage, readings, (inputs, times, name, adjustments, underneath)))
            })();
            let (stage, readings, opened) = match opened {
                Ok(x) => x,
                Err(e) => {
                    let _ = setup_tx.send(Err(e));
                    return;
                }
            };
            let inputs = opened.0.clone();
            let times = opened.1.clone();
            let underneath = opened.4.clone();
            // Per mesh, per curvenet (binding order): its adjustment prims.
            let per_curvenet: Vec<Vec<Vec<AdjustmentData>>> = inputs
                .iter()
                .enumerate()
                .map(|(m, (_, nets, _))| {
                    (0..nets.len())
                        .map(|k| opened.3[m].iter().filter(|a| a.curvenet == k).map(|a| a.data.clone()).collect())
                        .collect()
                })
                .collect();
            if setup_tx.send(Ok(opened)).is_err() {
                return;
            }
            // Serve frame reads until every ViewerStage (every sender) is gone.
            for (m, k, answer) in query_rx {
                let (mesh, nets, _) = &inputs[m];
                let _ = answer.send(
                    read_frame(&stage, mesh, nets, &readings[m], &per_curvenet[m], times[k])
                        .and_then(|f| underneath[m].frame(&stage, f, times[k])),
                );
            }
        })
        .map_err(|e| CliError::Io { context: "starting the stage reader thread".into(), source: e })?;
    let (inputs, times, name, mut adjustments, underneath) = setup_rx.recv().map_err(|_| {
        CliError::Input(format!("{}: the stage reader stopped while opening the stage", path.display()))
    })??;
    let query_tx = std::sync::Mutex::new(query_tx);
    let query_tx = Arc::new(query_tx);
    Ok(inputs
        .into_iter()
        .enumerate()
        .map(|(m, (mesh, nets, _))| {
            let queries = query_tx.clone();
            let n_frames = times.len();
            let frame: FrameSource = Arc::new(move |k: usize| {
                if k >= n_frames {
                    return Err(format!("frame {k} does not exist ({n_frames} frames)"));
                }
                let (tx, rx) = std::sync::mpsc::channel();
                queries
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .send((m, k, tx))
                    .map_err(|_| "the stage reader has stopped".to_string())?;
                rx.recv().map_err(|_| "the stage reader has stopped".to_string())?
            });
            let curvenets = nets.iter().map(|n| n.path.clone()).collect();
            ViewerStage::new(
                name.clone(),
                mesh.path.clone(),
                curvenets,
                times.clone(),
                underneath[m].request(BindingRequest::from_stage(&mesh, &nets)),
                frame,
            )
            .with_adjustments(std::mem::take(&mut adjustments[m]))
        })
        .collect())
}

/// The rig layers under a mesh's curvenets, as `curvenet bake` reads them:
/// its UsdSkel rig when the mesh is skinned (with its curvenets' spline
/// skinning), and its cage (`rel curvenet:cage`), coupled with the rig when
/// both are there. Each frame then carries the joint transforms and the
/// cage's edits, so the viewer draws what the bake writes.
#[derive(Clone, Default)]
struct Underneath {
    cage: Option<curvenet_schema::CageData>,
    skin: Option<(Arc<super::rig::JointReader>, Vec<CurvenetSkinSpec>)>,
}

impl Underneath {
    fn read(stage: &Stage, mesh: &MeshData, nets: &[CurvenetData]) -> CliResult<Self> {
        let cage = stage.cage(mesh)?;
        let skin = match stage.skin_rig(mesh)? {
            None => None,
            Some(rig) => {
                let skeleton = curvenet_core::Skeleton::new(&rig.parents, &rig.bind_transforms)
                    .map_err(|source| CliError::Core { context: rig.skeleton.clone(), source })?;
                let curvenets = nets
                    .iter()
                    .map(|n| {
                        Ok(match stage.curvenet_skinning(n)? {
                            CurvenetSkinning::None => CurvenetSkinSpec::None,
                            CurvenetSkinning::FromMesh => CurvenetSkinSpec::Mesh,
                            CurvenetSkinning::Weights { element_size, joint_indices, joint_weights } => {
                                CurvenetSkinSpec::Weights {
                                    element_size: element_size as u32,
                                    joint_indices,
                                    joint_weights,
                                }
                            }
                        })
                    })
                    .collect::<CliResult<Vec<_>>>()?;
                Some((Arc::new(super::rig::JointReader { rig, skeleton }), curvenets))
            }
        };
        Ok(Self { cage, skin })
    }

    /// The binding request with the cage and the rig.
    fn request(&self, mut request: BindingRequest) -> BindingRequest {
        if let Some((joints, curvenets)) = &self.skin {
            request = request.with_skin(&joints.rig, curvenets.clone());
        }
        match &self.cage {
            Some(cage) => request.with_cage(cage),
            None => request,
        }
    }

    /// `frame` with the joint transforms and the cage's edits at `time`.
    fn frame(&self, stage: &Stage, mut frame: FrameRequest, time: f64) -> Result<FrameRequest, String> {
        if let Some((joints, _)) = &self.skin {
            frame.joint_transforms = Some(joints.read_transforms(stage, Some(time)).map_err(|e| e.to_string())?);
        }
        if let Some(cage) = &self.cage {
            let edits = cage.frame(Some(time));
            frame.rest_cage = edits.rest_cage().map(<[_]>::to_vec);
            frame.posed_cage_offsets = edits.posed_cage_offsets().map(<[_]>::to_vec);
        }
        Ok(frame)
    }
}

/// The `CurvenetAdjustment` prims of a mesh's curvenets (`nets`, binding
/// order), as the bake reads them, each with its values at every time code
/// one of its attributes has a sample at (what an export keys among).
fn stage_adjustments(stage: &Stage, nets: &[CurvenetData]) -> CliResult<Vec<StageAdjustment>> {
    let mut out = Vec::new();
    for (k, net) in nets.iter().enumerate() {
        for data in stage.curvenet_adjustments(net)? {
            let mut times: Vec<f64> = data.attributes.iter().flat_map(|(_, t)| t.iter().copied()).collect();
            times.sort_by(f64::total_cmp);
            times.dedup();
            let mut alone = vec![Vec::new(); nets.len()];
            alone[k].push(data.clone());
            let keys = times
                .into_iter()
                .map(|t| Ok((t, stage.adjustments_at(&alone, Some(t))?.remove(0))))
                .collect::<CliResult<Vec<_>>>()?;
            out.push(StageAdjustment { curvenet: k, data, keys });
        }
    }
    Ok(out)
}

/// One mesh's frame at `time`, as the bake reads it: the posed pools (none
/// for a curvenet without time samples), the rest pose and the blend-shape
/// weights and order as `reading` says, the curvenets' adjustments
/// (`adjustments[k]`: curvenet `k`'s prims).
fn read_frame(
    stage: &Stage,
    mesh: &MeshData,
    nets: &[CurvenetData],
    reading: &FrameReading,
    adjustments: &[Vec<AdjustmentData>],
    time: f64,
) -> Result<FrameRequest, String> {
    let posed = nets
        .iter()
        .map(|n| stage.posed_pool(n, Some(time)))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| e.to_string())?;
    let rest = match reading.reads_rest {
        true => Some(stage.rest_points(mesh, Some(time)).map_err(|e| e.to_string())?),
        false => reading.bind_points.clone(),
    };
    let weights = if mesh.blend_shapes.is_empty() {
        None
    } else {
        Some(stage.blend_shape_weights(mesh, Some(time)).map_err(|e| e.to_string())?)
    };
    let adjustments = stage.adjustments_at(adjustments, Some(time)).map_err(|e| e.to_string())?;
    Ok(FrameRequest {
        posed: Some(posed),
        rest,
        blend_shape_weights: weights,
        blend_shape_mode: match reading.order {
            BlendShapeOrder::BeforeSkinning => BlendShapeMode::Before,
            BlendShapeOrder::AfterSolve => BlendShapeMode::After,
        },
        adjustments: adjustments.iter().map(AdjustmentSpec::from).collect(),
        ..FrameRequest::default()
    })
}
