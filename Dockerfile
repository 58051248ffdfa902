# Multi-stage build of the `curvenet` binary; by default it runs the service.
# Build: docker build -t curvenet .
# Serve: docker run --rm -p 8720:8720 -e CURVENET_TOKEN=... -e CURVENET_CACHE_BYTES=8GiB curvenet
# Bake:  docker run --rm -v "$PWD/shots:/shots" curvenet bake /shots/shot.usda --out /shots/baked.usda
# Other: docker run --rm -v "$PWD/fixtures:/data:ro" curvenet inspect /data/shots/hand_wave/shot.usda
#
# Builder and runtime are both Debian bookworm, so the binary's glibc matches.
FROM rust:1.95-bookworm AS build
WORKDIR /src
# Only what the workspace build needs (no target/, .venv or fixtures).
COPY Cargo.toml Cargo.lock ./
COPY core core
COPY schema schema
COPY server server
COPY tests tests
# openusd 0.8 declares rust-version 1.96 but builds on 1.95 (README, Toolchain).
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo build --release --locked --ignore-rust-version -p curvenet-server --bin curvenet \
    && cp target/release/curvenet /usr/local/bin/curvenet

FROM debian:bookworm-slim
RUN useradd --system --uid 10001 --home-dir /nonexistent --shell /usr/sbin/nologin curvenet
COPY --from=build /usr/local/bin/curvenet /usr/local/bin/curvenet
USER 10001:10001
# The service listens on all interfaces inside the container; the
# healthcheck reads the same variable (0.0.0.0 → 127.0.0.1).
ENV CURVENET_ADDR=0.0.0.0:8720
EXPOSE 8720
# `serve --healthcheck` GETs /healthz and exits 0 or 1: no curl in the image.
HEALTHCHECK --interval=15s --timeout=5s --start-period=10s --retries=3 \
    CMD ["/usr/local/bin/curvenet", "serve", "--healthcheck"]
# Docker stops containers with SIGTERM: the service drains requests in
# flight for CURVENET_DRAIN_TIMEOUT seconds (default 30; keep it below
# `docker stop --time`).
STOPSIGNAL SIGTERM
ENTRYPOINT ["/usr/local/bin/curvenet"]
CMD ["serve", "--addr", "0.0.0.0:8720"]
