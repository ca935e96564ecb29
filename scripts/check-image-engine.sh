# The container-engine route of scripts/check-image.sh (sourced by it after its "prepare" phase, which made
# $BASE, the debootstrapped bookworm, $ROOT, a prepared copy of it, and $STAGE, the build context): build the image
# with podman or docker and run it as a user would. Uses check-image.sh's phase_begin/phase_end and variables.
#
# - podman 4.3 (Debian bookworm) runs here with runc, not crun (crun refuses this machine's cgroups v1 set-up), and
#   with the open-file and process limits set to the host's hard limits: a private containers.conf
#   ($CACHE/containers.conf) says so;
# - `FROM debian:bookworm`: pulled when a registry answers; else the debootstrapped root, with Docker's debian
#   image's apt sources and policy-rc.d, is imported and tagged docker.io/library/debian:bookworm (said in the log);
# - the build uses the host's network (--network=host: no bridge set-up needed) and gets the host's extra CAs
#   (/usr/local/share/ca-certificates) through the Dockerfile's own EXTRA_CA_CERT argument, unless HOST_CAS=0.

IMAGE=${CHECK_IMAGE_TAG:-campo-solver:check}
ENGINE_SCENE=(run configs/example1.toml --set mesh.nx=8 --set mesh.ny=8 --set time.k=0.05 --no-progress)

engine_setup() {
  if [ "$ENGINE" = podman ]; then
    # podman's own defaults (1048576) are above this machine's hard limits, and runc then fails with "error
    # setting rlimit type 7 (nofile) / 6 (nproc): operation not permitted": the host's open-file hard limit, and
    # 32768 processes (65536 and the host's 96365 were refused here)
    local nproc=$(( $(ulimit -Hu) < 32768 ? $(ulimit -Hu) : 32768 ))
    cat > "$CACHE/containers.conf" <<EOF
[containers]
default_ulimits = ["nofile=$(ulimit -Hn):$(ulimit -Hn)", "nproc=$nproc:$nproc"]
pids_limit = 0

[engine]
runtime = "runc"
cgroup_manager = "cgroupfs"
events_logger = "file"
EOF
    export CONTAINERS_CONF="$CACHE/containers.conf"
  fi
  "$ENGINE" --version >&2
  "$ENGINE" info >/dev/null
}

engine_base() {
  local ref=docker.io/library/debian:bookworm
  if "$ENGINE" image exists "$ref" 2>/dev/null || "$ENGINE" image inspect "$ref" >/dev/null 2>&1; then
    echo "base image: $ref, already present" >&2
  elif timeout 120 "$ENGINE" pull -q "$ref" >&2; then
    echo "base image: $ref, pulled" >&2
  else
    echo "base image: no registry answered; importing the debootstrapped bookworm as $ref" >&2
    # $ROOT has the apt sources and policy-rc.d of Docker's image; its mounts are left out of the archive
    tar -C "$ROOT" --one-file-system --exclude=./proc --exclude=./sys --exclude=./dev --numeric-owner -c . |
      "$ENGINE" import --change 'CMD ["bash"]' - "$ref" >&2
  fi
}

engine_build() {
  local -a args=(--network=host --pull=never -t "$IMAGE" -f "$DOCKERFILE")
  local certs
  if [ "${HOST_CAS:-1}" = 1 ] && compgen -G "/usr/local/share/ca-certificates/*.crt" >/dev/null; then
    certs=$(cat /usr/local/share/ca-certificates/*.crt)
    args+=(--build-arg "EXTRA_CA_CERT=$certs")
    echo "build: the host's CAs given as EXTRA_CA_CERT ($(printf '%s' "$certs" | wc -c) bytes)" >&2
  fi
  [ "$ENGINE" = podman ] && args+=(--format docker)   # keeps ENTRYPOINT/CMD as Docker writes them
  timeout 90m "$ENGINE" build "${args[@]}" "$STAGE"
}

engine_scene() {
  local out=$CACHE/engine-out
  rm -rf "$out" && mkdir -p "$out" && chmod 777 "$out"
  "$ENGINE" run --rm --network=none -v "$out:/out" "$IMAGE" "${ENGINE_SCENE[@]}" --output /out/ex1 &&
    test -s "$out/ex1/timeseries.csv" &&
    "$ENGINE" run --rm --network=none --user 0:0 -v "$out:/out" "$IMAGE" "${ENGINE_SCENE[@]}" --output /out/ex1-root &&
    test -s "$out/ex1-root/timeseries.csv"
}

engine_tests() {
  local rc=0
  "$ENGINE" run --rm --network=none --entrypoint python "$IMAGE" -m pytest -q -m "not slow" -p no:cacheprovider || rc=$?
  if [ "$rc" = 5 ]; then echo "pytest collected no test (exit 5): not counted as a failure" >&2; return 0; fi
  return "$rc"
}

engine_mpi() {
  local out=$CACHE/engine-out
  "$ENGINE" run --rm --network=none -v "$out:/out" --entrypoint mpirun "$IMAGE" \
    -n 2 python -m solver "${ENGINE_SCENE[@]}" --output /out/ex1-np2 && test -s "$out/ex1-np2/timeseries.csv"
}

engine_size() {
  local bytes
  bytes=$("$ENGINE" image inspect "$IMAGE" --format '{{.Size}}')
  awk -v i="$IMAGE" -v b="$bytes" 'BEGIN { printf "image %s: %.0f bytes (%.2f GB)\n", i, b, b / 1e9 }' >&2
}

engine_phase() {  # name command...: a phase whose failure is recorded, and the check goes on
  local name=$1 rc=0
  shift
  phase_begin "$name"
  "$@" || rc=$?
  if [ "$rc" = 0 ]; then phase_end ok; else phase_end "FAILED (exit $rc)"; fi
  return 0
}

phase_begin "engine: $ENGINE set-up"
engine_setup
phase_end ok
phase_begin "engine: base image debian:bookworm"
engine_base
phase_end ok
phase_begin "engine: $ENGINE build -t $IMAGE"
engine_build
phase_end ok
engine_phase "engine: run ${ENGINE_SCENE[*]} (uid 1000, then --user 0:0)" engine_scene
engine_phase "engine: python -m pytest -q -m 'not slow'" engine_tests
engine_phase "engine: mpirun -n 2 python -m solver ${ENGINE_SCENE[*]}" engine_mpi
engine_phase "engine: image size" engine_size
