# Container image of the solver (dolfinx 0.5.2 from Debian bookworm).
#
# It installs through the Makefile, the project's one install path: the Debian
# packages with `make system-packages` (as root), then the virtual environment
# with `make install` as the non-root user `solver`, who owns /opt/solver/.venv.
#
# Build:
#   docker build -t campo-solver .
# Run a scene (the entrypoint is `python -m solver`; results go to a mounted folder):
#   mkdir -p out && docker run --rm -v "$PWD/out:/out" campo-solver run configs/example2.toml --output /out/ex2
#   docker run --rm campo-solver check configs/example1.toml
#   docker run --rm -v "$PWD/out:/out" campo-solver plot /out/ex2      # PNGs, rendered off-screen
# Run in parallel (MPI, 2 processes): replace the entrypoint with mpirun
#   docker run --rm -v "$PWD/out:/out" --entrypoint mpirun campo-solver \
#       -n 2 python -m solver run configs/example1.toml --output /out/ex1
# Own scenes: mount them too, e.g. -v "$PWD/scenes:/scenes" ... run /scenes/my.toml --output /out/my
# The output folder must be writable by uid 1000, or run as yourself with --user "$(id -u):$(id -g)"
# (any uid, root included: mpirun is allowed to run as root, and the compiled-form cache is shared).
# A slim image without the plotting stack (no matplotlib, pyvista/VTK; `plot` says so):
#   docker build --build-arg PLOTS=0 -t campo-solver:slim .
# Behind a TLS-intercepting proxy, give its CA certificate (PEM; one or a few certificates, not a whole CA
# bundle: a build argument reaches RUN as an environment variable, which holds at most 128 KiB) to the build:
#   docker build --build-arg EXTRA_CA_CERT="$(cat proxy-ca.pem)" -t campo-solver .
# Tests inside the image:
#   docker run --rm --entrypoint python campo-solver -m pytest -q -m "not slow"
#
# scripts/check-image.sh replays this file's RUN lines in a debootstrapped
# bookworm chroot (no Docker needed); it understands FROM, ARG, ENV, WORKDIR,
# USER, COPY [--chown=...], RUN (shell form), ENTRYPOINT (exec form), CMD, LABEL.
FROM debian:bookworm

ARG DEBIAN_FRONTEND=noninteractive
# PLOTS=0: no plotting stack (see the Makefile); EXTRA_CA_CERT: one or a few CA certificates (PEM text) to trust,
# for builds behind a TLS-intercepting proxy (apt and pip both use the system store then)
ARG PLOTS=1
ARG EXTRA_CA_CERT=""

# make runs the Makefile; ca-certificates lets pip reach PyPI over https. Each apt layer ends with apt-get clean
# and without the lists: the downloaded .debs and the indexes would stay in the layer (a base image made with
# debootstrap has no docker-clean hook that drops them)
RUN apt-get update -qq \
 && apt-get install -y -qq --no-install-recommends make ca-certificates \
 && apt-get clean && rm -rf /var/lib/apt/lists/* \
 && if [ -n "$EXTRA_CA_CERT" ]; then \
        printf '%s\n' "$EXTRA_CA_CERT" > /usr/local/share/ca-certificates/extra-ca.crt && update-ca-certificates; \
    fi

WORKDIR /opt/solver

# Debian packages first (a layer that only changes with the Makefile)
COPY Makefile ./
RUN make system-packages PLOTS=$PLOTS \
 && apt-get clean && rm -rf /var/lib/apt/lists/*

RUN useradd --create-home --uid 1000 --user-group --shell /bin/bash solver \
 && chown solver:solver /opt/solver

COPY --chown=solver:solver . /opt/solver

USER solver
ENV HOME=/home/solver \
    XDG_CACHE_HOME=/home/solver/.cache \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_CERT=/etc/ssl/certs/ca-certificates.crt \
    PYTHONUNBUFFERED=1
# the virtual environment /opt/solver/.venv, then the project in it (editable, with [dev] for pytest)
RUN make install PLOTS=$PLOTS

# mpirun refuses root unless told: `--user 0:0` (a root host user) must work like any other uid
ENV PATH=/opt/solver/.venv/bin:$PATH \
    OMPI_MCA_rmaps_base_oversubscribe=1 \
    OMPI_MCA_btl_vader_single_copy_mechanism=none \
    OMPI_ALLOW_RUN_AS_ROOT=1 \
    OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

# Compile the forms of the example scenes now (into /home/solver/.cache/fenics), so that a
# first run doesn't: two steps of each (k is a constant in the forms, so any k reuses them).
RUN for scene in configs/example*.toml; do \
        python -m solver run "$scene" --set time.T=0.02 --no-progress \
            --output "/tmp/precompile/$(basename "$scene" .toml)" || exit 1; \
    done \
 && rm -rf /tmp/precompile \
 && chmod -R a+rwX /home/solver/.cache

ENTRYPOINT ["python", "-m", "solver"]
CMD ["--help"]
