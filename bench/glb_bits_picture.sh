#!/usr/bin/env bash
# What the published GLB's normal and scalar bits do to the picture: runs the same Gray–Scott
# simulation (2 ranks, coloured by U, "merging": false) once per setting of the adaptor's
# "glb": {"normal_bits", "scalar_bits"}, takes a screenshot of the last step in the viewer
# (Chromium, software rendering, the viewer's default camera and colouring: by the field,
# viridis), once coloured by the field and once plain, and compares each picture with that of
# the first setting (the reference: 16 and 16 bits): the share of pixels that differ and the
# mean, 99th percentile and largest difference in 8-bit levels (of R, G, B; right of the side
# panel and above the legend, where the surface is). Also prints each
# setting's GLB bytes per triangle. Prints Markdown for docs/performance.md; keeps the PNGs in
# OUT (default /tmp/glb_bits_picture).
# Usage: bench/glb_bits_picture.sh [SIZE=192] [SUBSTEPS=60] [STEPS=20] [RESOLUTION=256] [OUT]
# Settings: $SETTINGS, default "16/16 10/10 8/10 8/8" (normal bits / scalar bits).
set -euo pipefail
out=$(realpath -m "${5:-/tmp/glb_bits_picture}")
bin=$(realpath -m "${LDIMESH_BIN:-$(dirname "$0")/../build/bin}")
cd "$(dirname "$0")/.."
size=${1:-192}
substeps=${2:-60}
steps=${3:-20}
resolution=${4:-256}
pid=
trap '[ -n "$pid" ] && kill "$pid" 2>/dev/null; true' EXIT
settings=${SETTINGS:-16/16 10/10 8/10 8/8}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$out"
last=$(printf 'step_%06d' "$steps")
for s in $settings; do
  n=${s%/*} v=${s#*/}
  dir="$out/n${n}_s${v}"
  rm -rf "$dir" && mkdir -p "$dir"
  printf '{"server": {"enabled": false}, "output_dir": "%s/steps", "resolution": %d, "keep": 2, "colour_by": "U", "merging": false, "glb": {"normal_bits": %d, "scalar_bits": %d}}\n' \
    "$dir" "$resolution" "$n" "$v" >"$dir/options.json"
  echo "glb_bits_picture: normal bits $n, scalar bits $v: simulating" >&2
  mpiexec -n 2 --bind-to none "$bin/ldimesh-grayscott" --size "$size" --substeps "$substeps" \
    --steps "$steps" --options "$dir/options.json" >"$dir/run.log"
  [ -f "$dir/steps/$last.glb" ] || { echo "glb_bits_picture: $dir/steps/$last.glb missing" >&2; exit 1; }
  # The viewer on that step alone: ldimesh serve on a free port, one screenshot per colouring.
  mkdir -p "$dir/last" && cp "$dir/steps/$last".* "$dir/last/"
  "$bin/ldimesh" serve --dir "$dir/last" --port 0 --token t >"$dir/serve.log" 2>&1 &
  pid=$!
  url=
  for _ in $(seq 100); do
    url=$(grep -o 'http://[^ ]*' "$dir/serve.log" | head -n 1 || true)
    [ -n "$url" ] && break
    sleep 0.1
  done
  [ -n "$url" ] || { kill "$pid"; echo "glb_bits_picture: the server printed no URL" >&2; exit 1; }
  node scripts/screenshot_viewer.mjs "$url" "$dir/field.png" 1200x800 >&2
  COLOUR=plain node scripts/screenshot_viewer.mjs "$url" "$dir/plain.png" 1200x800 >&2
  kill "$pid"
  wait "$pid" 2>/dev/null || true
  pid=
done
/usr/bin/python3 - "$out" "$last" $settings <<'PY'
import json, os, struct, sys, zlib
import numpy as np

def read_png(path):
    """RGB levels (0..255) of an 8-bit, non-interlaced RGB or RGBA PNG (Chromium's screenshots)."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    pos, idat = 8, b""
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            w, h, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and colour in (2, 6) and interlace == 0, path
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    n = 3 if colour == 2 else 4
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 1 + w * n)
    img = np.zeros((h, w * n), np.int32)
    for y in range(h):  # undo the per-row filters (PNG spec, 9.2)
        f, row = raw[y, 0], raw[y, 1:].astype(np.int32)
        up = img[y - 1] if y else np.zeros(w * n, np.int32)
        if f == 0:
            img[y] = row
        elif f == 1:  # Sub: a running sum per channel
            img[y] = (np.cumsum(row.reshape(w, n), axis=0) & 255).reshape(-1)
        elif f == 2:
            img[y] = (row + up) & 255
        elif f in (3, 4):
            out = np.zeros(w * n, np.int32)
            for x in range(w * n):
                left = out[x - n] if x >= n else 0
                ul = up[x - n] if x >= n else 0
                if f == 3:
                    pred = (left + up[x]) // 2
                else:
                    pa, pb, pc = abs(up[x] - ul), abs(left - ul), abs(left + up[x] - 2 * ul)
                    pred = left if pa <= pb and pa <= pc else (up[x] if pb <= pc else ul)
                out[x] = (row[x] + pred) & 255
            img[y] = out
        else:
            raise ValueError(f"{path}: unknown PNG filter {f}")
    return img.reshape(h, w, n)[..., :3].astype(float)
out, last, settings = sys.argv[1], sys.argv[2], sys.argv[3:]
def folder(s):
    n, v = s.split("/")
    return os.path.join(out, f"n{n}_s{v}")
ref = folder(settings[0])
print(f"Gray–Scott, step {last[5:].lstrip('0')}, coloured by U; pictures 1200 × 800 against "
      f"{settings[0]} (normal / scalar bits)\n")
print("| normal / scalar bits | triangles | bytes / triangle | colouring | pixels that differ "
      "| mean difference (levels) | 99th percentile | largest |")
print("|---|---|---|---|---|---|---|---|")
# The surface's part of a picture: right of the side panel (whose timings and sizes differ from
# run to run) and above the legend.
reference = {c: read_png(os.path.join(ref, c + ".png"))[:700, 310:] for c in ("field", "plain")}
for s in settings:
    d = folder(s)
    meta = json.load(open(os.path.join(d, "steps", last + ".json")))
    for colouring in ("field", "plain"):
        a = reference[colouring]
        b = read_png(os.path.join(d, colouring + ".png"))[:700, 310:]
        diff = np.abs(a - b)
        per_pixel = diff.max(axis=2)
        print(f"| {s} | {meta['triangles']} | {meta['bytes'] / meta['triangles']:.2f} | "
              f"{colouring} | {100.0 * (per_pixel > 0).mean():.1f} % | {diff.mean():.3f} | "
              f"{np.percentile(per_pixel, 99):.0f} | {per_pixel.max():.0f} |")
PY
