#!/bin/sh
# Compose v2 for the suite's check of deploy/compose.yaml (tests/test_container.py): Debian bookworm packages only
# docker-compose 1.29; the Debian release after it (trixie) packages Compose v2 as a program with no dependency but
# libc. Its .deb is fetched from Debian's archive with a private apt state (the machine's sources stay as they are)
# and only the program is unpacked: nothing is installed. Usage: fetch_compose_v2.sh TARGET
set -eu
target=$1
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/lists/partial" "$work/deb" "$(dirname "$target")"
echo "deb http://deb.debian.org/debian trixie main" > "$work/sources.list"
apt_options="-o Dir::Etc::sourcelist=$work/sources.list -o Dir::Etc::sourceparts=- -o Dir::State::Lists=$work/lists -o APT::Get::List-Cleanup=0 -o Debug::NoDropPrivs=1 -o APT::Sandbox::User=root"
# shellcheck disable=SC2086
apt-get -qq $apt_options update
# shellcheck disable=SC2086
(cd "$work/deb" && apt-get -qq $apt_options download docker-compose)
dpkg-deb -x "$work"/deb/docker-compose_*.deb "$work/unpacked"
cp "$work/unpacked/usr/libexec/docker/cli-plugins/docker-compose" "$target"
"$target" version
