//! Prometheus metrics, one registry per [`crate::AppState`] (not the global
//! recorder), so several services in one process (the tests) count apart.

use std::time::Duration;

use metrics::{Counter, Gauge, Histogram, Key, Label, Level, Metadata, Recorder, SharedString, Unit};
use metrics_exporter_prometheus::{PrometheusBuilder, PrometheusHandle, PrometheusRecorder};

const METADATA: Metadata<'static> = Metadata::new(module_path!(), Level::INFO, Some(module_path!()));

/// Latency buckets, seconds: 0.5 ms to 60 s.
const BUCKETS: [f64; 16] =
    [0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 30.0, 60.0];

pub struct Metrics {
    recorder: PrometheusRecorder,
    handle: PrometheusHandle,
    pub cache_hits: Counter,
    pub cache_misses: Counter,
    pub cache_evictions: Counter,
    pub cache_bytes: Gauge,
    pub cache_entries: Gauge,
    pub cache_capacity_bytes: Gauge,
    pub bindings_computed: Counter,
    pub saturated: Counter,
    pub connections_refused: Counter,
    pub bindings_cancelled: Counter,
    pub solves_in_flight: Gauge,
    pub batch_memory_bytes: Gauge,
    pub bindings_running: Gauge,
    pub frames_solved: Counter,
    pub solve_seconds: Histogram,
    pub bind_seconds: Histogram,
    /// Binding store (`store.rs`): blobs found.
    pub store_hits: Counter,
    /// Binding store lookups that found no blob.
    pub store_misses: Counter,
    /// Blobs the caller found invalid (it increments this, then removes the blob).
    pub store_rejected: Counter,
    /// Binding store backend failures (I/O, S3), also those that did not fail the call.
    pub store_errors: Counter,
    /// Entries the store deleted to stay within its size limit.
    pub store_evictions: Counter,
    /// Blobs written to the store.
    pub store_written: Counter,
    /// Bytes of the blobs written to the store.
    pub store_written_bytes: Counter,
    /// Bytes of the blobs read from the store (hits).
    pub store_read_bytes: Counter,
    /// The store's size after the last put or usage listing.
    pub store_bytes: Gauge,
    /// One hit's load (read, and recency refreshed).
    pub store_load_seconds: Histogram,
    /// One blob's write (without the eviction sweep after it).
    pub store_write_seconds: Histogram,
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

impl Metrics {
    pub fn new() -> Self {
        let recorder = PrometheusBuilder::new().set_buckets(&BUCKETS).expect("non-empty buckets").build_recorder();
        let handle = recorder.handle();
        let counter = |name: &'static str, help: &'static str| {
            recorder.describe_counter(name.into(), None, SharedString::const_str(help));
            recorder.register_counter(&Key::from_static_name(name), &METADATA)
        };
        let gauge = |name: &'static str, unit: Option<Unit>, help: &'static str| {
            recorder.describe_gauge(name.into(), unit, SharedString::const_str(help));
            recorder.register_gauge(&Key::from_static_name(name), &METADATA)
        };
        let histogram = |name: &'static str, help: &'static str| {
            recorder.describe_histogram(name.into(), Some(Unit::Seconds), SharedString::const_str(help));
            recorder.register_histogram(&Key::from_static_name(name), &METADATA)
        };
        recorder.describe_counter(
            "curvenet_http_requests_total".into(),
            None,
            SharedString::const_str("HTTP requests by route, method and status"),
        );
        recorder.describe_histogram(
            "curvenet_http_request_duration_seconds".into(),
            Some(Unit::Seconds),
            SharedString::const_str("HTTP request latency by route"),
        );
        Self {
            cache_hits: counter("curvenet_cache_hits_total", "binding lookups answered from the cache"),
            cache_misses: counter("curvenet_cache_misses_total", "binding lookups that computed the binding"),
            cache_evictions: counter(
                "curvenet_cache_evictions_total",
                "bindings evicted to stay within the cache size",
            ),
            cache_bytes: gauge("curvenet_cache_bytes", Some(Unit::Bytes), "estimated bytes of the cached bindings"),
            cache_entries: gauge("curvenet_cache_entries", None, "cached bindings"),
            cache_capacity_bytes: gauge("curvenet_cache_capacity_bytes", Some(Unit::Bytes), "the cache size limit"),
            bindings_computed: counter(
                "curvenet_bindings_computed_total",
                "bindings computed (cut-mesh and factorisation)",
            ),
            saturated: counter(
                "curvenet_saturated_total",
                "requests refused with 503 because every solve permit was taken",
            ),
            connections_refused: counter(
                "curvenet_connections_refused_total",
                "connections answered 503 and closed because --max-connections were open",
            ),
            bindings_cancelled: counter(
                "curvenet_bindings_cancelled_total",
                "bindings stopped before their end (client gone, time limit, shutdown)",
            ),
            solves_in_flight: gauge(
                "curvenet_solves_in_flight",
                None,
                "solve permits held (running or queued for a core)",
            ),
            batch_memory_bytes: gauge(
                "curvenet_batch_memory_bytes",
                Some(Unit::Bytes),
                "bytes reserved by frames:batch requests in flight (--max-batch-memory)",
            ),
            bindings_running: gauge("curvenet_bindings_running", None, "bindings being computed now"),
            frames_solved: counter("curvenet_frames_solved_total", "frames deformed"),
            solve_seconds: histogram(
                "curvenet_frame_solve_seconds",
                "one frame's solve (core deform and blend shapes)",
            ),
            bind_seconds: histogram("curvenet_bind_seconds", "one binding's computation"),
            store_hits: counter("curvenet_store_hits_total", "binding store lookups that found a blob"),
            store_misses: counter("curvenet_store_misses_total", "binding store lookups that found no blob"),
            store_rejected: counter(
                "curvenet_store_rejected_total",
                "blobs read from the binding store that failed validation (and were removed)",
            ),
            store_errors: counter("curvenet_store_errors_total", "binding store backend failures (file system or S3)"),
            store_evictions: counter(
                "curvenet_store_evictions_total",
                "binding store entries evicted to stay within its size limit",
            ),
            store_written: counter("curvenet_store_written_total", "blobs written to the binding store"),
            store_written_bytes: counter(
                "curvenet_store_written_bytes_total",
                "bytes of the blobs written to the binding store",
            ),
            store_read_bytes: counter(
                "curvenet_store_read_bytes_total",
                "bytes of the blobs read from the binding store",
            ),
            store_bytes: gauge(
                "curvenet_store_bytes",
                Some(Unit::Bytes),
                "bytes in the binding store after the last write or listing",
            ),
            store_load_seconds: histogram(
                "curvenet_store_load_seconds",
                "one blob's load from the binding store (hits)",
            ),
            store_write_seconds: histogram("curvenet_store_write_seconds", "one blob's write to the binding store"),
            recorder,
            handle,
        }
    }

    /// Counts one HTTP request.
    pub fn request(&self, route: &str, method: &str, status: u16, elapsed: Duration) {
        let labels = vec![
            Label::new("route", route.to_string()),
            Label::new("method", method.to_string()),
            Label::new("status", status.to_string()),
        ];
        self.recorder
            .register_counter(&Key::from_parts("curvenet_http_requests_total", labels), &METADATA)
            .increment(1);
        let labels = vec![Label::new("route", route.to_string())];
        self.recorder
            .register_histogram(&Key::from_parts("curvenet_http_request_duration_seconds", labels), &METADATA)
            .record(elapsed.as_secs_f64());
    }

    /// Drains the histograms' pending samples (run periodically, so a server
    /// nobody scrapes does not accumulate them).
    pub fn upkeep(&self) {
        self.handle.run_upkeep();
    }

    /// The Prometheus text exposition.
    pub fn render(&self) -> String {
        self.handle.render()
    }
}
