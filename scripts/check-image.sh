#!/usr/bin/env bash
# Builds and tests the image with podman or docker where one runs, and proves the Dockerfile's install steps on a
# fresh Debian bookworm without one (a chroot replay).
#
#   sudo bash scripts/check-image.sh [--engine auto|podman|docker|chroot] [--fresh] [--keep-mounts]
#
# --engine auto (the default): podman if `podman info` works, else docker if `docker info` does (a docker CLI
# without a daemon does not), else the chroot replay; the log says which and why. Steps 1-3 serve both routes;
# with an engine, 4-7 are scripts/check-image-engine.sh's: build the image (FROM pulled, or the debootstrapped
# root imported as debian:bookworm where no registry answers), run the scene as uid 1000 and as root, the tests,
# mpirun -n 2, and print the image's size. Without one:
#
# 1. host:        installs debootstrap on the host if it is missing (apt-get)
# 2. debootstrap: makes a minimal bookworm root ("debootstrap --variant=minbase",
#                 the variant Docker's debian images are built from) under
#                 $SOLVER_IMAGE_ROOT (default /var/tmp/solver-image-root)/base, from
#                 the mirror this machine's apt uses; kept between runs (--fresh remakes it)
# 3. prepare:     copies that base to .../work (every run starts from the clean base,
#                 as a docker build starts from the image), writes its apt sources,
#                 resolv.conf and hosts, and mounts /proc, /sys, /dev (+ /dev/pts and
#                 a 64 MiB /dev/shm as in Docker); all are unmounted on exit
# 4. dockerfile:  replays the Dockerfile in the root: FROM (must be debian:bookworm),
#                 ARG, ENV, WORKDIR, USER, COPY [--chown] (the build context being the
#                 project's git-tracked and untracked-not-ignored files, less
#                 .dockerignore) and each RUN with /bin/sh -c as Docker does
#                 (as USER through runuser, in WORKDIR, with only the image's env)
# 5. scene:       the ENTRYPOINT with a short Example 1 as the image's final user
# 6. tests:       python -m pytest -q -m "not slow" in the image's WORKDIR (if tests/ has tests)
# 7. mpi:         mpirun -n 2 of the short scene, as the non-root user
# Prints the time of each phase; exits non-zero if any phase failed.
#
# Environment: SOLVER_IMAGE_ROOT (cache folder), DOCKERFILE (default ./Dockerfile),
# DEBIAN_MIRROR (default: read from /etc/apt/sources.list{,.d/*}), HOST_CAS=0 (do not
# give the build the host's own CAs of /usr/local/share/ca-certificates; see below).
# The debs downloaded by apt are kept in $SOLVER_IMAGE_ROOT/apt-archives between runs.
set -euo pipefail

usage() { sed -n '2,38s/^# \{0,1\}//p' "$0"; }

FRESH=0
KEEP_MOUNTS=0
ENGINE=auto
while [ $# -gt 0 ]; do
  case "$1" in
    --fresh) FRESH=1 ;;
    --keep-mounts) KEEP_MOUNTS=1 ;;
    --engine) shift; ENGINE=${1:-} ;;
    -h|--help) usage; exit 0 ;;
    *) echo "check-image: unknown argument: $1" >&2; usage >&2; exit 2 ;;
  esac
  shift
done

PROJECT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
CACHE=${SOLVER_IMAGE_ROOT:-/var/tmp/solver-image-root}
DOCKERFILE=${DOCKERFILE:-$PROJECT/Dockerfile}
BASE=$CACHE/base
ROOT=$CACHE/work
ARCHIVES=$CACHE/apt-archives
STAGE=$CACHE/context
SUITE=bookworm
DEFAULT_PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin

say() { printf '\n=== %s\n' "$*" >&2; }
die() { printf 'check-image: %s\n' "$*" >&2; exit 1; }

[ "$(id -u)" = 0 ] || die "must run as root (debootstrap, chroot and mount need it)"
[ -f "$DOCKERFILE" ] || die "no Dockerfile at $DOCKERFILE"

# ---------------------------------------------------------------- phases and timing
PHASE_NAMES=()
PHASE_SECS=()
PHASE_STATUS=()
FAILED=0
CUR_PHASE=""
CUR_START=0
T0=$SECONDS

phase_begin() { CUR_PHASE=$1; CUR_START=$SECONDS; say "phase: $1"; }
phase_end() {  # status
  local s=$(( SECONDS - CUR_START ))
  PHASE_NAMES+=("$CUR_PHASE"); PHASE_SECS+=("$s"); PHASE_STATUS+=("$1")
  printf '=== phase %s: %s in %dm%02ds\n' "$CUR_PHASE" "$1" $(( s / 60 )) $(( s % 60 )) >&2
  [ "$1" = ok ] || [ "$1" = skipped ] || [ "$1" = reused ] || FAILED=1
  CUR_PHASE=""
}

summary() {
  local i s
  printf '\n%-60s %10s  %s\n' "phase" "time" "status" >&2
  for i in "${!PHASE_NAMES[@]}"; do
    s=${PHASE_SECS[$i]}
    printf '%-60.60s %6dm%02ds  %s\n' "${PHASE_NAMES[$i]}" $(( s / 60 )) $(( s % 60 )) "${PHASE_STATUS[$i]}" >&2
  done
  s=$(( SECONDS - T0 ))
  printf '%-60s %6dm%02ds\n' "total" $(( s / 60 )) $(( s % 60 )) >&2
}

# ---------------------------------------------------------------- mounts
unmount_under() {  # every mount at or below $1, deepest first
  local dir=$1 m
  awk -v d="$dir" '$2 == d || index($2, d "/") == 1 { print $2 }' /proc/mounts | sort -r |
    while read -r m; do
      umount "$m" 2>/dev/null || umount -l "$m" || echo "check-image: could not unmount $m" >&2
    done
}

on_exit() {
  local rc=$?
  if [ -n "$CUR_PHASE" ]; then phase_end "FAILED (exit $rc)"; fi
  if [ "$KEEP_MOUNTS" = 1 ]; then
    echo "check-image: --keep-mounts: $ROOT stays mounted; unmount with: umount -R $ROOT/{proc,sys,dev,var/cache/apt/archives}" >&2
  else
    unmount_under "$ROOT"
  fi
  summary
  if [ "$rc" = 0 ] && [ "$FAILED" = 1 ]; then rc=1; fi
  if [ "$rc" = 0 ]; then echo "check-image: PASSED" >&2; else echo "check-image: FAILED" >&2; fi
  exit "$rc"
}
trap on_exit EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

remove_tree() {  # never follows into mounts (a bound /dev!)
  unmount_under "$1"
  if awk -v d="$1" '$2 == d || index($2, d "/") == 1 { f = 1 } END { exit !f }' /proc/mounts; then
    die "$1 still has mounts; not removing it"
  fi
  rm -rf --one-file-system "$1"
}

mount_root() {
  mount -t proc proc "$ROOT/proc"
  mount -t sysfs sysfs "$ROOT/sys"
  mount -t devtmpfs -o mode=0755,nosuid udev "$ROOT/dev"
  mkdir -p "$ROOT/dev/pts" "$ROOT/dev/shm"
  mount -t devpts -o newinstance,ptmxmode=0666,mode=0620,gid=5 devpts "$ROOT/dev/pts"
  mount -t tmpfs -o mode=1777,nosuid,nodev,size=64m shm "$ROOT/dev/shm"
  mkdir -p "$ARCHIVES/partial" "$ROOT/var/cache/apt/archives"
  mount --bind "$ARCHIVES" "$ROOT/var/cache/apt/archives"
}

# ---------------------------------------------------------------- apt mirror of this host
# Prints the URIs of the enabled apt sources (one-line and deb822 formats) whose suite is $1.
host_uris() {
  local suite=$1 f
  for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
    [ -r "$f" ] || continue
    awk -v s="$suite" '
      /^[[:space:]]*deb[[:space:]]/ {
        i = 2
        if ($i ~ /^\[/) { while (i <= NF && $i !~ /\]$/) i++; i++ }
        if ($(i + 1) == s) print $i
      }' "$f"
  done
  for f in /etc/apt/sources.list.d/*.sources; do
    [ -r "$f" ] || continue
    awk -v s="$suite" '
      BEGIN { RS = ""; FS = "\n" }
      {
        types = ""; uris = ""; suites = ""; enabled = "yes"
        for (j = 1; j <= NF; j++) {
          line = $j
          if (line ~ /^[[:space:]]*#/) continue
          if (match(line, /^[A-Za-z-]+:/)) {
            key = tolower(substr(line, 1, RLENGTH - 1)); val = substr(line, RLENGTH + 1)
            if (key == "types") types = val
            else if (key == "uris") uris = val
            else if (key == "suites") suites = val
            else if (key == "enabled") enabled = val
          }
        }
        gsub(/^[[:space:]]+|[[:space:]]+$/, "", enabled)
        if (enabled == "no" || (" " types " ") !~ /[[:space:]]deb[[:space:]]/) next
        n = split(suites, sv, /[[:space:]]+/)
        for (k = 1; k <= n; k++) if (sv[k] == s) { m = split(uris, uv, /[[:space:]]+/); for (u = 1; u <= m; u++) if (uv[u] != "") print uv[u]; break }
      }' "$f"
  done
}

MIRROR=${DEBIAN_MIRROR:-$(host_uris "$SUITE" | head -n1)}
MIRROR=${MIRROR:-http://deb.debian.org/debian}
SECURITY_MIRROR=$(host_uris "$SUITE-security" | head -n1)
SECURITY_MIRROR=${SECURITY_MIRROR:-http://deb.debian.org/debian-security}
echo "check-image: project $PROJECT, Dockerfile $DOCKERFILE, cache $CACHE" >&2
echo "check-image: mirror $MIRROR (security: $SECURITY_MIRROR)" >&2

# ---------------------------------------------------------------- 0. which engine
case "$ENGINE" in
  auto)
    ENGINE=chroot
    probe=$(mktemp)
    if ! command -v podman >/dev/null; then echo "check-image: no podman" >&2
    elif podman --runtime runc info >/dev/null 2>"$probe"; then ENGINE=podman
    else echo "check-image: podman does not run: $(tail -n1 "$probe")" >&2; fi
    if [ "$ENGINE" = chroot ]; then
      if ! command -v docker >/dev/null; then echo "check-image: no docker" >&2
      elif docker info >/dev/null 2>"$probe"; then ENGINE=docker
      else echo "check-image: docker does not run: $(grep -m1 -i 'cannot\|error' "$probe")" >&2; fi
    fi
    rm -f "$probe" ;;
  podman|docker|chroot) ;;
  *) echo "check-image: --engine must be auto, podman, docker or chroot, not '$ENGINE'" >&2; exit 2 ;;
esac
echo "check-image: route: $ENGINE" >&2

# ---------------------------------------------------------------- 1. host
phase_begin "host: debootstrap installed"
if ! command -v debootstrap >/dev/null 2>&1; then
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends debootstrap
fi
command -v debootstrap >/dev/null || die "debootstrap did not install"
phase_end ok

# ---------------------------------------------------------------- 2. debootstrap
phase_begin "debootstrap: minbase $SUITE"
mkdir -p "$CACHE"
remove_tree "$ROOT"  # a root left by an earlier run (also frees mounts under it)
if [ "$FRESH" = 1 ] || [ ! -f "$CACHE/base.ok" ]; then
  rm -f "$CACHE/base.ok"
  remove_tree "$BASE"
  debootstrap --variant=minbase "$SUITE" "$BASE" "$MIRROR" > "$CACHE/debootstrap.log" 2>&1 ||
    { tail -n 30 "$CACHE/debootstrap.log" >&2; die "debootstrap failed (log: $CACHE/debootstrap.log)"; }
  rm -rf "$BASE/var/cache/apt/archives/"*.deb "$BASE/var/lib/apt/lists/"*
  touch "$CACHE/base.ok"
  phase_end ok
else
  echo "reusing $BASE (made $(date -r "$CACHE/base.ok" '+%F %T'); --fresh to remake it)" >&2
  phase_end reused
fi

# ---------------------------------------------------------------- 3. prepare the root
phase_begin "prepare: copy base, apt sources, mounts, build context"
cp -a "$BASE" "$ROOT"
# apt sources as in Docker's debian:bookworm image, from this host's mirror
rm -f "$ROOT/etc/apt/sources.list"
cat > "$ROOT/etc/apt/sources.list.d/debian.sources" <<EOF
Types: deb
URIs: $MIRROR
Suites: $SUITE $SUITE-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: $SECURITY_MIRROR
Suites: $SUITE-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
# no services start from package scripts (Docker's debian images have the same file)
printf '#!/bin/sh\nexit 101\n' > "$ROOT/usr/sbin/policy-rc.d"
chmod 755 "$ROOT/usr/sbin/policy-rc.d"
# name resolution, as Docker provides it
rm -f "$ROOT/etc/resolv.conf" "$ROOT/etc/hosts"
cat /etc/resolv.conf > "$ROOT/etc/resolv.conf"
cat /etc/hosts > "$ROOT/etc/hosts"
mount_root
# Behind a TLS-intercepting proxy, as on some build machines, the host trusts extra CAs
# of its own (/usr/local/share/ca-certificates): the root gets them too (the image's
# ca-certificates picks them up when it installs), and the build's pip is pointed at the
# system store (PyPI's pip trusts its own bundle only), like `docker build` would need
# there; HOST_CAS=0 turns this off. The image itself is unchanged by it.
BUILD_ENV=()
if [ "${HOST_CAS:-1}" = 1 ] && compgen -G "/usr/local/share/ca-certificates/*.crt" >/dev/null; then
  mkdir -p "$ROOT/usr/local/share/ca-certificates"
  cp /usr/local/share/ca-certificates/*.crt "$ROOT/usr/local/share/ca-certificates/"
  BUILD_ENV=(PIP_CERT=/etc/ssl/certs/ca-certificates.crt)
  echo "host CAs copied into the root; build env: ${BUILD_ENV[*]}" >&2
fi

# the build context: git-tracked files and untracked ones git does not ignore, less .dockerignore
IGNORE=()
if [ -f "$PROJECT/.dockerignore" ]; then
  while IFS= read -r pat || [ -n "$pat" ]; do
    pat=${pat%%$'\r'}
    pat="${pat#"${pat%%[![:space:]]*}"}"; pat="${pat%"${pat##*[![:space:]]}"}"
    case "$pat" in ''|'#'*) continue ;; '!'*) echo "check-image: .dockerignore exception '$pat' not supported; ignored" >&2; continue ;; esac
    pat=${pat#/}; pat=${pat#./}; pat=${pat%/}
    IGNORE+=("$pat")
  done < "$PROJECT/.dockerignore"
fi
ignored() {  # is path $1 (relative) excluded by .dockerignore? ("*" may cross "/", close enough)
  local path=$1 pat p anydepth i j n
  local -a parts
  IFS=/ read -ra parts <<< "$path"
  n=${#parts[@]}
  for pat in "${IGNORE[@]}"; do
    p=$pat; anydepth=0
    if [[ $p == '**/'* ]]; then anydepth=1; p=${p#'**/'}; fi
    for (( j = 1; j <= n; j++ )); do           # prefix of j components
      for (( i = 0; i < (anydepth ? j : 1); i++ )); do   # starting at component i
        local cand
        cand=$(IFS=/; echo "${parts[*]:i:j-i}")
        # shellcheck disable=SC2053
        [[ $cand == $p ]] && return 0
      done
    done
  done
  return 1
}
context_files() {
  if git -c safe.directory='*' -C "$PROJECT" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    git -c safe.directory='*' -C "$PROJECT" ls-files -z --cached --others --exclude-standard
  else
    (cd "$PROJECT" && find . -type f -print0 | sed -z 's|^\./||')
  fi
}
remove_tree "$STAGE"
mkdir -p "$STAGE"
nfiles=0
while IFS= read -r -d '' f; do
  [ -e "$PROJECT/$f" ] || [ -L "$PROJECT/$f" ] || continue   # deleted in the working tree
  ignored "$f" && continue
  (cd "$PROJECT" && cp -P --preserve=mode,timestamps --parents "$f" "$STAGE/")
  nfiles=$((nfiles + 1))
done < <(context_files | sort -zu)
echo "build context: $nfiles files" >&2
# `docker build` sends what .dockerignore leaves, git's ignore rules aside: name the big leftovers
if git -c safe.directory='*' -C "$PROJECT" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  while IFS= read -r -d '' f; do
    f=${f%/}
    ignored "$f" && continue
    echo "check-image: warning: $f is ignored by git but not by .dockerignore: docker build would send it ($(du -sh "$PROJECT/$f" | cut -f1))" >&2
  done < <(git -c safe.directory='*' -C "$PROJECT" ls-files -z --others --ignored --exclude-standard --directory)
fi
phase_end ok

if [ "$ENGINE" != chroot ]; then
  # shellcheck source=scripts/check-image-engine.sh
  source "$PROJECT/scripts/check-image-engine.sh"
  exit 0
fi

# ---------------------------------------------------------------- 4. the Dockerfile
declare -A ENVS=([PATH]=$DEFAULT_PATH)   # the image's ENV (debian:bookworm sets PATH)
ENV_ORDER=(PATH)
declare -A ARGS=()
ARG_ORDER=()
CUR_USER=root
CUR_WD=/
ENTRYPOINT=()
CMD=()
FROM_SEEN=0

expand() {  # Docker's $VAR / ${VAR} substitution in ENV, WORKDIR, USER, COPY
  local s=$1 out="" name re='^([^$]*)\$(\{([A-Za-z_][A-Za-z0-9_]*)\}|([A-Za-z_][A-Za-z0-9_]*))(.*)$'
  while [[ $s =~ $re ]]; do
    name=${BASH_REMATCH[3]:-${BASH_REMATCH[4]}}
    out+=${BASH_REMATCH[1]}
    if [ -n "${ENVS[$name]+x}" ]; then out+=${ENVS[$name]}; elif [ -n "${ARGS[$name]+x}" ]; then out+=${ARGS[$name]}; fi
    s=${BASH_REMATCH[5]}
  done
  printf '%s' "$out$s"
}

tokens() {  # split $1 into words honouring "..." '...' and \ ; prints them NUL-separated
  local s=$1 c q="" w="" have=0 i
  for (( i = 0; i < ${#s}; i++ )); do
    c=${s:i:1}
    if [ -n "$q" ]; then
      if [ "$c" = "$q" ]; then q=""
      elif [ "$c" = '\' ] && [ "$q" = '"' ]; then i=$((i + 1)); w+=${s:i:1}
      else w+=$c; fi
    elif [ "$c" = '"' ] || [ "$c" = "'" ]; then q=$c; have=1
    elif [ "$c" = '\' ]; then i=$((i + 1)); w+=${s:i:1}; have=1
    elif [[ $c == [[:space:]] ]]; then
      if [ "$have" = 1 ]; then printf '%s\0' "$w"; w=""; have=0; fi
    else w+=$c; have=1; fi
  done
  if [ "$have" = 1 ]; then printf '%s\0' "$w"; fi
}

json_array() {  # ["a", "b"] -> NUL-separated words (strings without escaped quotes)
  local s=$1
  s=${s#*[}; s=${s%]*}
  printf '%s' "$s" | grep -o '"[^"]*"' | sed 's/^"//; s/"$//' | tr '\n' '\0'
}

set_env() { [ -n "${ENVS[$1]+x}" ] || ENV_ORDER+=("$1"); ENVS[$1]=$2; }

in_root() {  # user workdir command... : as a docker RUN / docker run does it, inside the root
  local user=$1 wd=$2 home k
  shift 2
  local -a envs=()
  home=$(chroot "$ROOT" getent passwd "$user" | cut -d: -f6 || true)
  [ -n "$home" ] || { [ "$user" = root ] && home=/root; } || die "no user $user in the image"
  envs+=("HOME=$home" "HOSTNAME=solver-image")
  for k in "${ARG_ORDER[@]}"; do envs+=("$k=${ARGS[$k]}"); done
  envs+=("${BUILD_ENV[@]}")
  for k in "${ENV_ORDER[@]}"; do envs+=("$k=${ENVS[$k]}"); done
  local -a limit=()
  [ -z "${IN_ROOT_TIMEOUT:-}" ] || limit=(timeout --kill-after=30 "$IN_ROOT_TIMEOUT")
  if [ "$user" = root ] || [ "$user" = 0 ]; then
    "${limit[@]}" chroot "$ROOT" /usr/bin/env -i -C "$wd" "${envs[@]}" "$@"
  else
    "${limit[@]}" chroot "$ROOT" /usr/sbin/runuser -u "$user" -- /usr/bin/env -i -C "$wd" "${envs[@]}" "$@"
  fi
}

abs_path() {  # relative to the current WORKDIR
  case "$1" in /*) printf '%s' "$1" ;; *) printf '%s/%s' "${CUR_WD%/}" "$1" ;; esac
}

do_copy() {
  local -a words=() srcs=()
  local w owner="" dest src target top
  while IFS= read -r -d '' w; do words+=("$w"); done < <(tokens "$1")
  for w in "${words[@]}"; do
    case "$w" in
      --chown=*) owner=$(expand "${w#--chown=}") ;;
      --link|--link=*) ;;
      --*) die "COPY option $w is not supported by this check" ;;
      *) srcs+=("$(expand "$w")") ;;
    esac
  done
  [ ${#srcs[@]} -ge 2 ] || die "COPY needs a source and a destination: $1"
  dest=${srcs[-1]}; unset 'srcs[-1]'
  case "$dest" in */) target=$(abs_path "$dest") ;; *) target=$(abs_path "$dest") ;; esac
  for src in "${srcs[@]}"; do
    src=${src#./}; src=${src%/}
    [[ $src == *[*?[]* ]] && die "COPY wildcards are not supported by this check: $src"
    if [ -z "$src" ] || [ "$src" = . ]; then
      # the entries of the context into the folder; an existing folder keeps its owner
      if [ ! -d "$ROOT$target" ]; then
        mkdir -p "$ROOT$target"
        [ -z "$owner" ] || chroot "$ROOT" chown "$owner" "$target"
      fi
      for top in "$STAGE"/* "$STAGE"/.[!.]*; do
        [ -e "$top" ] || [ -L "$top" ] || continue
        cp -a "$top" "$ROOT$target/"
        [ -z "$owner" ] || chroot "$ROOT" chown -R "$owner" "$target/${top##*/}"
      done
    elif [ -d "$STAGE/$src" ]; then
      mkdir -p "$ROOT$target"
      cp -a "$STAGE/$src/." "$ROOT$target/"
      [ -z "$owner" ] || chroot "$ROOT" chown -R "$owner" "$target"
    elif [ -e "$STAGE/$src" ]; then
      local to=$target
      if [[ $dest == */ ]] || [ ${#srcs[@]} -gt 1 ] || [ -d "$ROOT$target" ]; then
        mkdir -p "$ROOT$target"; to=$target/${src##*/}
      else
        mkdir -p "$ROOT$(dirname "$target")"
      fi
      cp -a "$STAGE/$src" "$ROOT$to"
      [ -z "$owner" ] || chroot "$ROOT" chown "$owner" "$to"
    else
      die "COPY: $src is not in the build context (tracked, and not in .dockerignore?)"
    fi
  done
}

# join continuation lines, drop comments and blank lines -> one instruction a line
mapfile -t INSTRUCTIONS < <(awk '
  /^[[:space:]]*#/ { next }
  {
    line = $0; sub(/\r$/, "", line)
    if (line ~ /\\[[:space:]]*$/) { sub(/\\[[:space:]]*$/, "", line); buf = buf line " "; cont = 1; next }
    if (cont && line ~ /^[[:space:]]*$/) next
    buf = buf line; cont = 0
    if (buf !~ /^[[:space:]]*$/) print buf
    buf = ""
  }
  END { if (buf !~ /^[[:space:]]*$/) print buf }' "$DOCKERFILE")

run_no=0
for ins in "${INSTRUCTIONS[@]}"; do
  ins="${ins#"${ins%%[![:space:]]*}"}"
  kw=${ins%%[[:space:]]*}; kw=${kw^^}
  rest="${ins#*[[:space:]]}"; rest="${rest#"${rest%%[![:space:]]*}"}"
  case "$kw" in
    FROM)
      [ "$FROM_SEEN" = 0 ] || die "multi-stage builds are not supported by this check"
      FROM_SEEN=1
      read -r image _ <<< "$rest"
      case "$image" in
        debian:bookworm|debian:12|docker.io/debian:bookworm|docker.io/library/debian:bookworm) ;;
        *) die "FROM $image: this check emulates debian:bookworm only" ;;
      esac ;;
    ARG)
      name=${rest%%=*}
      if [[ $rest == *=* ]]; then val=$(tokens "${rest#*=}" | tr '\0' ' '); val=${val% }; else val=""; fi
      [ -n "${ARGS[$name]+x}" ] || ARG_ORDER+=("$name")
      ARGS[$name]=$val ;;
    ENV)
      mapfile -d '' -t words < <(tokens "$rest")
      if [[ ${words[0]} != *=* ]]; then      # legacy "ENV KEY value with spaces"
        set_env "${words[0]}" "$(expand "${rest#*[[:space:]]}")"
      else
        declare -A pending=()
        pending_order=()
        for w in "${words[@]}"; do            # all values see the env before this ENV, as in Docker
          pending[${w%%=*}]=$(expand "${w#*=}"); pending_order+=("${w%%=*}")
        done
        for k in "${pending_order[@]}"; do set_env "$k" "${pending[$k]}"; done
        unset pending
      fi ;;
    WORKDIR)
      CUR_WD=$(abs_path "$(expand "$rest")")
      mkdir -p "$ROOT$CUR_WD" ;;
    USER)
      CUR_USER=$(expand "$rest"); CUR_USER=${CUR_USER%%:*} ;;
    COPY)
      phase_begin "dockerfile: COPY $rest"
      do_copy "$rest"
      phase_end ok ;;
    RUN)
      [[ $rest == --* ]] && die "RUN options ($rest) are not supported by this check"
      [[ $rest == \[* ]] && die "exec-form RUN is not supported by this check"
      run_no=$((run_no + 1))
      phase_begin "dockerfile: RUN #$run_no ($CUR_USER) $rest"
      echo "+ $rest" >&2
      in_root "$CUR_USER" "$CUR_WD" /bin/sh -c "$rest"
      phase_end ok ;;
    ENTRYPOINT)
      if [[ $rest == \[* ]]; then mapfile -d '' -t ENTRYPOINT < <(json_array "$rest"); else ENTRYPOINT=(/bin/sh -c "$rest"); fi ;;
    CMD)
      if [[ $rest == \[* ]]; then mapfile -d '' -t CMD < <(json_array "$rest"); else CMD=(/bin/sh -c "$rest"); fi ;;
    LABEL|EXPOSE|VOLUME|STOPSIGNAL|HEALTHCHECK|MAINTAINER) ;;
    *) die "Dockerfile instruction $kw is not supported by this check" ;;
  esac
done
[ "$FROM_SEEN" = 1 ] || die "the Dockerfile has no FROM"
[ ${#ENTRYPOINT[@]} -gt 0 ] || die "the Dockerfile has no ENTRYPOINT"
[ "$CUR_USER" != root ] && [ "$CUR_USER" != 0 ] || die "the image runs as root: its last USER should be a non-root user"
echo "image user: $CUR_USER, workdir: $CUR_WD, entrypoint: ${ENTRYPOINT[*]}" >&2

# ---------------------------------------------------------------- 5.-7. runs, as `docker run` would
ARGS=()   # build arguments are not in the image
ARG_ORDER=()
BUILD_ENV=()
SCENE=(run configs/example1.toml --set mesh.nx=8 --set mesh.ny=8 --set time.k=0.05 --no-progress)

soft() {  # name timeout command...: a phase whose failure is recorded, and the check goes on
  local name=$1 rc=0
  IN_ROOT_TIMEOUT=$2
  shift 2
  phase_begin "$name"
  "$@" || rc=$?
  IN_ROOT_TIMEOUT=""
  if [ "$rc" = 0 ]; then phase_end ok; else phase_end "FAILED (exit $rc)"; fi
  return 0
}
has_outputs() { [ -n "$(find "$ROOT$1" -type f 2>/dev/null | head -n1)" ] || { echo "no results in $1" >&2; return 1; }; }

scene() { in_root "$CUR_USER" "$CUR_WD" "${ENTRYPOINT[@]}" "${SCENE[@]}" --output /tmp/out && has_outputs /tmp/out; }
soft "scene: ${ENTRYPOINT[*]} ${SCENE[*]}" 20m scene

if compgen -G "$ROOT$CUR_WD/tests/test_*.py" >/dev/null || compgen -G "$ROOT$CUR_WD/tests/*_test.py" >/dev/null; then
  tests() {
    local rc=0
    in_root "$CUR_USER" "$CUR_WD" python -m pytest -q -m "not slow" -p no:cacheprovider || rc=$?
    if [ "$rc" = 5 ]; then echo "pytest collected no test (exit 5): not counted as a failure" >&2; return 0; fi
    return "$rc"
  }
  soft "tests: python -m pytest -q -m 'not slow'" 60m tests
else
  phase_begin "tests: python -m pytest -q -m 'not slow'"
  echo "no tests in $CUR_WD/tests yet" >&2
  phase_end skipped
fi

mpi_scene() { in_root "$CUR_USER" "$CUR_WD" mpirun -n 2 "${ENTRYPOINT[@]}" "${SCENE[@]}" --output /tmp/out-mpi && has_outputs /tmp/out-mpi; }
soft "mpi: mpirun -n 2 ${ENTRYPOINT[*]} ${SCENE[*]}" 20m mpi_scene
