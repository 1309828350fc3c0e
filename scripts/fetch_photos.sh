#!/usr/bin/env bash
# Install the Debian photos of colorglove_ros/config/photos.yaml into data/photos/ (synthetic backgrounds):
# download the pinned Debian package with apt-get, unpack it with dpkg-deb, copy the listed
# photos, and check every photo (pip-shipped ones too) against its sha256. Safe to run again:
# nothing is downloaded when all photos are present and match. Fails loudly otherwise.
#
#   COLORGLOVE_PHOTOS_DEB=/path/to/mate-backgrounds_1.26.0-1_all.deb  use a .deb already here
#   COLORGLOVE_PHOTO_MANIFEST, COLORGLOVE_PHOTO_DIR  another manifest / photo folder
#   PYTHON=...  the Python with this package's dependencies (default: the venv's, else python3)
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
if [ -z "${PYTHON:-}" ]; then
    if [ -x "$repo/.venv/bin/python" ]; then PYTHON=$repo/.venv/bin/python; else PYTHON=python3; fi
fi
options=()
if [ -n "${COLORGLOVE_PHOTO_MANIFEST:-}" ]; then options+=(--manifest "$COLORGLOVE_PHOTO_MANIFEST"); fi
if [ -n "${COLORGLOVE_PHOTO_DIR:-}" ]; then options+=(--photo-dir "$COLORGLOVE_PHOTO_DIR"); fi
photos() {
    PYTHONPATH="$repo/colorglove_ros${PYTHONPATH:+:$PYTHONPATH}" "$PYTHON" -m colorglove_ros.core.synthetic.photos \
        ${options[@]+"${options[@]}"} "$@"
}
fail() { echo "fetch_photos: error: $*" >&2; exit 1; }

if photos check >/dev/null 2>&1; then
    photos check
    exit 0
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

packages=$(photos debian-packages) || fail "cannot read the photo manifest"
for spec in $packages; do
    name=${spec%%=*}
    version=${spec#*=}
    deb=${COLORGLOVE_PHOTOS_DEB:-}
    if [ -n "$deb" ]; then
        [ -f "$deb" ] || fail "COLORGLOVE_PHOTOS_DEB=$deb does not exist"
        echo "==> using $deb for $name"
    else
        command -v apt-get >/dev/null || fail "apt-get not found: the photos come from Debian's $name package (or set COLORGLOVE_PHOTOS_DEB to its .deb)"
        echo "==> downloading $name=$version"
        mkdir -p "$work/$name"
        download() { (cd "$work/$name" && apt-get download "$1" >"$work/apt.log" 2>&1); }
        if ! download "$name=$version"; then
            if [ "$(id -u)" = 0 ]; then
                echo "==> apt-get update (package lists may be missing)"
                apt-get update -qq >"$work/update.log" 2>&1 || { cat "$work/update.log" >&2; fail "apt-get update failed"; }
            fi
            if ! download "$name=$version"; then
                cat "$work/apt.log" >&2
                echo "==> $name=$version is not in this machine's archive; trying its current $name (the photos are still checked against their sha256)"
                download "$name" || { cat "$work/apt.log" >&2; fail "cannot download $name with apt-get (no network to the Debian archive? not a Debian/Ubuntu machine?)"; }
            fi
        fi
        debs=("$work/$name"/*.deb)
        [ -f "${debs[0]}" ] || fail "apt-get download $name left no .deb"
        deb=${debs[0]}
    fi
    command -v dpkg-deb >/dev/null || fail "dpkg-deb not found: cannot unpack $deb"
    dpkg-deb -x "$deb" "$work/root" || fail "dpkg-deb cannot unpack $deb"
done

photos install "$work/root" || fail "installing the photos failed (see above)"
