#!/usr/bin/env bash
# Build the DriveBench image without a Docker daemon (buildah) and check what the Dockerfile promises by running it
# (podman): the server runs as uid 10001, its data lands in the /app/var volume, the first start makes the admin
# from a secret file (a restart leaves the users alone), and the image's HEALTHCHECK reports healthy.
#
#   scripts/verify_container.sh                      # from the repository's root, as root (or rootless podman)
#
# Without a reachable image registry, STANDIN_BASE=1 first makes a stand-in for python:3.11-slim from Debian's
# packages (mmdebstrap: bookworm minbase + python3, python3-venv, ca-certificates) and tags it with that name.
# Environment: PODMAN (the podman command with its global options), RUN_FLAGS (extra `podman run` options),
# DRIVEBENCH_DATABASE_URL (a database the container reaches instead of SQLite in the volume; with RUN_FLAGS
# containing --network host, a PostgreSQL on this machine), KEEP=1 (leave the container, volume and image).
# On the project's machine (no CAP_SYS_RESOURCE, hybrid cgroups) it ran with
#   BUILDAH_ISOLATION=chroot PODMAN="podman --runtime runc --cgroup-manager cgroupfs" \
#   RUN_FLAGS="--network host --ulimit nofile=4096:4096 --ulimit nproc=4096:4096" STANDIN_BASE=1
set -euo pipefail

PODMAN=${PODMAN:-podman}
RUN_FLAGS=${RUN_FLAGS:---network host}
IMAGE=${IMAGE:-localhost/drivebench-verify}
NAME=drivebench-verify-$$
VOLUME=$NAME-var
WORK=$(mktemp -d)
PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
PASSWORD="verify-$(od -An -N8 -tx1 /dev/urandom | tr -d ' \n')"

say() { printf '== %s\n' "$*"; }
fail() { printf 'FAILED: %s\n' "$*" >&2; $PODMAN logs "$NAME" >&2 2>/dev/null || true; exit 1; }
cleanup() {
    if [ "${KEEP:-0}" != 1 ]; then
        $PODMAN rm --force "$NAME" >/dev/null 2>&1 || true
        $PODMAN volume rm --force "$VOLUME" >/dev/null 2>&1 || true
    fi
    rm -rf "$WORK"
}
trap cleanup EXIT

if [ "${STANDIN_BASE:-0}" = 1 ]; then
    say "stand-in base python:3.11-slim from Debian packages (mmdebstrap)"
    mmdebstrap --quiet --variant=minbase --include=python3,python3-venv,ca-certificates bookworm "$WORK/rootfs.tar"
    base=$(buildah from scratch)
    buildah add --quiet "$base" "$WORK/rootfs.tar" /
    buildah config --env PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin --env LANG=C.UTF-8 \
        --cmd python3 "$base"
    buildah commit --quiet "$base" docker.io/library/python:3.11-slim >/dev/null
    buildah rm "$base" >/dev/null
    rm -f "$WORK/rootfs.tar"
fi

say "build $IMAGE (buildah, Docker format: OCI images drop HEALTHCHECK)"
buildah bud --quiet --pull=never --format docker -v /etc/ssl/certs:/etc/ssl/certs:ro -t "$IMAGE" . >/dev/null

start() {  # the image's own ENTRYPOINT and CMD, with the admin secret mounted as compose mounts it
    local db=()
    [ -n "${DRIVEBENCH_DATABASE_URL:-}" ] && db=(-e "DRIVEBENCH_DATABASE_URL=$DRIVEBENCH_DATABASE_URL")
    # shellcheck disable=SC2086
    $PODMAN run --detach --name "$NAME" $RUN_FLAGS -v "$VOLUME:/app/var" \
        -v "$WORK/admin_password:/run/secrets/admin_password:ro" "${db[@]}" \
        -e DRIVEBENCH_PORT="$PORT" -e DRIVEBENCH_ADMIN_USER=plantadmin \
        -e DRIVEBENCH_ADMIN_PASSWORD_FILE=/run/secrets/admin_password "$IMAGE" >/dev/null
}
healthy() {
    for _ in $(seq 60); do
        if $PODMAN healthcheck run "$NAME" >/dev/null 2>&1; then return 0; fi
        sleep 1
    done
    fail "the health check did not pass within 60 s"
}
sign_in() {  # HTTP status of a sign-in as plantadmin with password $1
    curl --silent --output /dev/null --write-out '%{http_code}' -H 'Content-Type: application/json' \
        --data "{\"name\": \"plantadmin\", \"password\": \"$1\"}" "http://127.0.0.1:$PORT/api/auth/login"
}

printf '%s\n' "$PASSWORD" >"$WORK/admin_password"
chmod 0644 "$WORK/admin_password"  # read by uid 10001 in the container
$PODMAN volume create "$VOLUME" >/dev/null
say "first start"
start
healthy
say "health check: $($PODMAN inspect --format '{{.State.Health.Status}}' "$NAME")"
user=$($PODMAN top "$NAME" user huser args 2>/dev/null | awk '/drivebench serve/ {print $1 " (host " $2 ")"}')
say "server process runs as: $user"
case "$user" in drivebench*|10001*) ;; *) fail "the server does not run as the drivebench user" ;; esac
[ "$(sign_in "$PASSWORD")" = 200 ] || fail "the admin from the secret file cannot sign in"
# shellcheck disable=SC2086
[ "$($PODMAN run --rm $RUN_FLAGS -v "$VOLUME:/app/var" --entrypoint stat "$IMAGE" -c '%u' /app/var)" = 10001 ] \
    || fail "the volume is not the drivebench user's"
if [ -z "${DRIVEBENCH_DATABASE_URL:-}" ]; then
    # shellcheck disable=SC2086
    listing=$($PODMAN run --rm $RUN_FLAGS -v "$VOLUME:/app/var" --entrypoint ls "$IMAGE" -ln /app/var)
    grep -q " 10001 10001 .* drivebench.db$" <<<"$listing" || fail "no database of the drivebench user in the volume"
fi
# shellcheck disable=SC2086
$PODMAN run --rm $RUN_FLAGS --entrypoint ls "$IMAGE" /app/backend/drivebench/web/__pycache__ \
    | grep -q '^app\.cpython-.*\.pyc$' || fail "no compiled modules in the image (every start would compile them)"
logs=$($PODMAN logs "$NAME" 2>&1)
grep -q "First start: created the admin plantadmin" <<<"$logs" || fail "no first-start message"
if grep -qF "$PASSWORD" <<<"$logs"; then fail "the password was printed"; fi

say "restart with another password in the secret file: the users stay as they are"
$PODMAN stop --time 20 "$NAME" >/dev/null
$PODMAN rm "$NAME" >/dev/null
printf 'another password\n' >"$WORK/admin_password"
start
healthy
grep -q "Users exist already" <<<"$($PODMAN logs "$NAME" 2>&1)" || fail "the restart did not leave the users alone"
[ "$(sign_in "$PASSWORD")" = 200 ] && [ "$(sign_in 'another password')" = 401 ] \
    || fail "the restart changed the admin's password"
say "verified: non-root server, data in the volume, first admin from the secret file once, health check healthy"
