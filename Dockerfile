# Multi-stage build of the `curvenet` binary.
# Build: docker build -t curvenet .
# Run:   docker run --rm -v "$PWD/fixtures:/data:ro" curvenet inspect /data/shots/hand_wave/shot.usda
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
# openusd 0.8 declares rust-version 1.96 but builds on 1.95 (README, Toolchain).
RUN cargo build --release --locked --ignore-rust-version --bin curvenet

FROM debian:bookworm-slim
RUN useradd --system --uid 10001 --home-dir /nonexistent --shell /usr/sbin/nologin curvenet
COPY --from=build /src/target/release/curvenet /usr/local/bin/curvenet
USER curvenet
ENTRYPOINT ["/usr/local/bin/curvenet"]
CMD ["--help"]
