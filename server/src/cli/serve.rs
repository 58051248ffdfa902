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
use curvenet_server::{AppState, BakeFailure, BakeJob, Baker, Config};

use super::{CliError, CliResult};

#[derive(clap::Args)]
pub struct Args {
    /// Address to listen on (port 0: any free port; the bound address is printed).
    #[arg(long, env = "CURVENET_ADDR", default_value = "127.0.0.1:8720")]
    pub addr: String,
    /// Memory for cached bindings (estimated), e.g. 2GiB, 512MiB, 1000000.
    #[arg(long, env = "CURVENET_CACHE_BYTES", default_value = "2GiB", value_parser = parse_bytes)]
    pub cache_bytes: u64,
    /// Largest request body, e.g. 256MiB.
    #[arg(long, env = "CURVENET_BODY_LIMIT", default_value = "256MiB", value_parser = parse_bytes)]
    pub body_limit: u64,
    /// Solves (frames, bindings, bakes) admitted at once, running or queued
    /// for a solve thread; beyond it: 503 with Retry-After.
    #[arg(long, env = "CURVENET_MAX_SOLVES", default_value_t = curvenet_server::DEFAULT_MAX_SOLVES)]
    pub max_solves: usize,
    /// Threads solving frames (0: one per core).
    #[arg(long, env = "CURVENET_SOLVE_THREADS", default_value_t = 0)]
    pub solve_threads: usize,
    /// Seconds requests in flight may finish after SIGTERM/SIGINT.
    #[arg(long, env = "CURVENET_DRAIN_TIMEOUT", default_value_t = 30.0)]
    pub drain_timeout: f64,
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
}

/// Parses a byte count with an optional suffix: K/KB (1000), KiB (1024), M/MB, MiB, G/GB, GiB.
fn parse_bytes(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let split = s.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(s.len());
    let (num, unit) = s.split_at(split);
    let num: f64 = num.parse().map_err(|_| format!("{s:?} is not a byte count (e.g. 512MiB, 2GiB, 1000000)"))?;
    let scale: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" => 1e3,
        "kib" => 1024.0,
        "m" | "mb" => 1e6,
        "mib" => 1024.0 * 1024.0,
        "g" | "gb" => 1e9,
        "gib" => 1024.0 * 1024.0 * 1024.0,
        other => return Err(format!("unknown unit {other:?} (B, KB, KiB, MB, MiB, GB, GiB)")),
    };
    Ok((num * scale) as u64)
}

pub fn run(args: &Args) -> CliResult {
    if args.healthcheck {
        healthcheck(&args.addr);
    }
    if !(args.drain_timeout.is_finite() && args.drain_timeout >= 0.0) {
        return Err(CliError::Input(format!("--drain-timeout must be a non-negative number of seconds, got {}", args.drain_timeout)));
    }
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
        drain_timeout: Duration::from_secs_f64(args.drain_timeout),
        token: args.token.clone().filter(|t| !t.is_empty()),
        bake_roots: args.bake_roots.clone(),
    };
    let state = AppState::new(config, Some(baker())).map_err(|e| CliError::Input(e.to_string()))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("curvenet-http")
        .build()
        .map_err(|e| CliError::Io { context: "starting the runtime".into(), source: e })?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind(&args.addr)
            .await
            .map_err(|e| CliError::Io { context: format!("binding {}", args.addr), source: e })?;
        let addr = listener.local_addr().map_err(|e| CliError::Io { context: "reading the bound address".into(), source: e })?;
        println!("listening on http://{addr}");
        use std::io::Write as _;
        let _ = std::io::stdout().flush();
        tracing::info!(%addr, auth = state.config().token.is_some(), cache_bytes = state.config().cache_bytes, "curvenet serve");
        curvenet_server::run(listener, state, shutdown_signal())
            .await
            .map_err(|e| CliError::Io { context: format!("serving on {addr}"), source: e })
    })?;
    tracing::info!("stopped");
    Ok(())
}

/// Resolves on SIGINT (Ctrl-C) or SIGTERM (docker stop, Kubernetes).
async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
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
        s.write_all(request.as_bytes()).is_ok() && s.read_to_string(&mut answer).is_ok() && answer.starts_with("HTTP/1.1 200")
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
        let mut argv = vec!["bake".into(), job.stage.clone().into_os_string(), "--out".into(), job.output.clone().into_os_string()];
        if let Some(f) = &job.frames {
            argv.push("--frames".into());
            argv.push(f.into());
        }
        argv.push("--quiet".into());
        let bake = Bake::try_parse_from(argv).map_err(|e| BakeFailure::Input(e.to_string()))?;
        super::bake::run(&bake.args).map_err(|e| {
            if e.exit_code() == 75 { BakeFailure::Retry(e.to_string()) } else { BakeFailure::Input(e.to_string()) }
        })
    })
}
