#!/usr/bin/env bash
# The cluster route under a real Slurm: a one-node Slurm on this machine runs the job script of
# docs/install/cluster.md (sbatch, --signal=B:TERM@..., --requeue, srun --mpi=pmix -n 2) with a 1-minute time limit;
# the scheduler's warning signal stops the run at the end of a level with a checkpoint, the job requeues itself and
# continues with --restart, until the run is complete; its result must equal an uninterrupted run's (1e-12).
#
#   sudo bash scripts/check-slurm.sh          (root: installs slurm-wlm and munge with apt-get, starts the daemons)
#
# Environment: CHECK_SLURM_N and CHECK_SLURM_K (Example 1's mesh n x n and time step, default 64 and 0.0001:
# 10,000 levels, about a minute on 2 unloaded cores beside the uninterrupted run, so that the limit cuts it; at
# 8 x 8 and k = 0.001 the whole run took 2 s), CHECK_SLURM_MINUTES (the time limit, default 1),
# CHECK_SLURM_DIR (scratch folder, default a new one under /tmp, removed on success). The daemons are stopped on exit.
# The controller checks limits at 30-second ticks: with a 1-minute limit and the warning 30 s before it, each try
# gets 20-30 s, so on a loaded machine, where start-up takes most of that, a try may advance a single level
# (CHECK_SLURM_MINUTES=2 gives it 60-90 s).
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY="$repo/.venv/bin/python"
K=${CHECK_SLURM_K:-0.0001}
N=${CHECK_SLURM_N:-64}
MINUTES=${CHECK_SLURM_MINUTES:-1}
work=${CHECK_SLURM_DIR:-$(mktemp -d /tmp/check-slurm.XXXXXX)}
mkdir -p "$work"
say() { printf 'check-slurm: %s\n' "$*" >&2; }
die() { say "$*"; exit 1; }

[ "$(id -u)" = 0 ] || die "must run as root (it installs and starts munge and Slurm)"
[ -x "$PY" ] || die "no $PY: run 'make install' first"

# ------------------------------------------------------------------ install (Debian bookworm: Slurm 22.05)
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
  say "installing slurm-wlm munge"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null
fi

# ------------------------------------------------------------------ start munge and a one-node Slurm
conf="$work/slurm.conf"
node="$(hostname -s)"
mkdir -p "$work/state" "$work/spool" "$work/log" /run/munge
chown munge:munge /run/munge
[ -s /etc/munge/munge.key ] || die "no /etc/munge/munge.key (the munge package makes it)"
started=()
stop_daemons() {
  local pids=()
  for pidfile in "$work/slurmd.pid" "$work/slurmctld.pid" "${started[@]}"; do
    [ -s "$pidfile" ] && pids+=("$(cat "$pidfile")")
  done
  [ ${#pids[@]} -eq 0 ] && return 0
  kill "${pids[@]}" 2>/dev/null || true
  for _ in $(seq 30); do kill -0 "${pids[@]}" 2>/dev/null || return 0; sleep 0.5; done
  kill -9 "${pids[@]}" 2>/dev/null || true
}
trap stop_daemons EXIT
trap 'exit 130' INT   # so that the EXIT trap stops the daemons on a signal too
trap 'exit 143' TERM
if ! pgrep -u munge -x munged >/dev/null; then
  runuser -u munge -- /usr/sbin/munged
  started+=(/run/munge/munged.pid)
fi
# DefMemPerCPU: without it a job takes all the memory; MailProg: the controller logs an error without one
cat > "$conf" <<EOF
ClusterName=check
SlurmctldHost=$node
SlurmUser=root
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
DefMemPerCPU=1000
MailProg=/bin/true
ReturnToService=2
KillWait=30
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/log/slurmctld.log
SlurmdLogFile=$work/log/slurmd.log
NodeName=$node CPUs=2 RealMemory=20000 State=UNKNOWN
PartitionName=check Nodes=$node Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF="$conf"
slurmctld -c -i -f "$conf"
slurmd -f "$conf"
for _ in $(seq 60); do sinfo -h -o %T 2>/dev/null | grep -q idle && break; sleep 1; done
sinfo -h -o %T | grep -q idle || die "the node did not come up idle: $(sinfo 2>&1); see $work/log"
say "Slurm up: $(sinfo -h -o '%P %D %T %c')"

# ------------------------------------------------------------------ the job script, as docs/install/cluster.md has it
job="$work/campo.sbatch"
awk '/<!-- check-slurm: job script -->/ {on = 1; next} on && /^```bash/ {inblock = 1; next}
     inblock && /^```/ {exit} inblock {print}' "$repo/docs/install/cluster.md" > "$job"
grep -q '^#SBATCH --requeue' "$job" && grep -q 'srun --mpi=pmix' "$job" \
  || die "no job script found after '<!-- check-slurm: job script -->' in docs/install/cluster.md"

scene=(configs/example1.toml --set "mesh.nx=$N" --set "mesh.ny=$N" --set "time.k=$K" --set output.every=200)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1

# the uninterrupted run, outside Slurm, while the job runs
(cd "$repo" && mpirun -n 2 "$PY" -m solver run "${scene[@]}" --output "$work/reference" --no-progress) \
  > "$work/reference.log" 2>&1 &
ref=$!

# the job, with a short limit and the warning 30 s before it (the command line overrides the script's #SBATCH)
jobid=$(cd "$repo" && sbatch --parsable --time="$MINUTES" --signal=B:TERM@30 --output="$work/job.log" --chdir="$repo" \
        "$job" "${scene[@]:0:1}" "$work/run" "${scene[@]:1}")
say "job $jobid submitted: $job"
t0=$SECONDS
last=""
pending_since=""
while :; do
  state=$(squeue -h -j "$jobid" -o %T 2>/dev/null || true)
  if [ -z "$state" ]; then state=$(sacct -n -X -j "$jobid" -o State 2>/dev/null | head -1 | xargs || true); fi
  if [ -z "$state" ]; then state=$(scontrol show job "$jobid" 2>/dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p'); fi
  if [ "$state" != "$last" ]; then say "$(( SECONDS - t0 )) s: $state"; last=$state; fi
  case "$state" in
    PENDING)  # a requeued job waits ~2 minutes (BeginTime); start it sooner, but not at once: started within a
      # second of the requeue, its batch script was refused ("Job credential revoked") and the job ended FAILED
      [ -n "$pending_since" ] || pending_since=$SECONDS
      if [ $(( SECONDS - pending_since )) -ge 5 ]; then scontrol update JobId="$jobid" StartTime=now 2>/dev/null || true; fi ;;
    RUNNING) pending_since="" ;;
    COMPLETED) break ;;
    FAILED|TIMEOUT|CANCELLED*|NODE_FAIL|OUT_OF_MEMORY|BOOT_FAIL|DEADLINE|PREEMPTED)
      cat "$work/job.log" >&2; die "job $jobid ended $state" ;;
  esac
  [ $(( SECONDS - t0 )) -lt 3600 ] || { scancel "$jobid"; die "job $jobid not done after an hour"; }
  sleep 2
done
wait "$ref" || { cat "$work/reference.log" >&2; die "the uninterrupted run failed"; }

restarts=$(scontrol show job "$jobid" | sed -n 's/.*Restarts=\([0-9]*\).*/\1/p')
say "job $jobid COMPLETED after $(( SECONDS - t0 )) s, requeued ${restarts:-?} times; its log:"
sed 's/^/    /' "$work/job.log" >&2
stops=$(grep -c '^stopped by SIGTERM' "$work/job.log" || true)
[ "${restarts:-0}" -ge 1 ] && [ "$stops" -ge 1 ] \
  || die "the time limit never stopped the run (requeued ${restarts:-0} times, $stops stops): set CHECK_SLURM_K smaller"

# ------------------------------------------------------------------ the same result as the uninterrupted run
cd "$repo"
"$PY" - "$work/run" "$work/reference" <<'EOF'
"""The requeued run's CSV columns and node fields at every written level against the uninterrupted run's (1e-12)."""
import sys

from solver.post.compare import compare_runs

diff = compare_runs(sys.argv[1], sys.argv[2])
assert diff.same, diff.differences[:5]
print(f"check-slurm: {diff.levels} levels and {diff.written} written fields equal the uninterrupted run's "
      f"(worst relative difference {diff.worst:.1e})")
EOF
stop_daemons  # before the pid files go with the scratch folder
rm -rf "$work"
say "ok"
