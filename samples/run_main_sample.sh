#!/usr/bin/env bash
# The main job: installs what is missing, builds corofem, runs the paper's Fig. 8 beam headless with
# the co-rotational and the linear formulation, and draws both shapes and the tip displacement.
# Outputs: out/fig8_corot/, out/fig8_linear/ (probes.csv, VTK series, summary.json) and
# out/fig8_beam.png; with ../shared/data, the coupled liver, the interactive frame loop and the renderer
# (out/renderer/, out/renderer.png, out/renderer.gif).
set -euo pipefail
cd "$(dirname "$0")/.."
bash cmake/debian-deps.sh
bash cmake/configure-build.sh --target corofem_cli interactive
# The renderer sample needs the Vulkan backend and zlib (both installed above).
if grep -q '^COROFEM_WITH_VULKAN:BOOL=ON' build/CMakeCache.txt && grep -q '^COROFEM_WITH_ZLIB:BOOL=ON' build/CMakeCache.txt; then
  cmake --build build -j"$(nproc)" --target renderer
fi
scene=samples/fig8_beam/fig8_beam.json
./build/corofem run "$scene" --out out/fig8_corot
./build/corofem run "$scene" --out out/fig8_linear --set bodies.0.formulation=linear
/usr/bin/python3 samples/fig8_beam/plot_fig8.py --corot out/fig8_corot --linear out/fig8_linear --out out/fig8_beam.png
for run in fig8_corot fig8_linear; do
  /usr/bin/python3 - "out/$run/summary.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
tip = s["final_probe_displacement"].get("tip", [float("nan")] * 3)
print(f"{sys.argv[1]}: {s['bodies'][0]['formulation']}, {s['steps_taken']} steps on {s['backend']}, "
      f"median {1e3 * s['wall_time_per_step_s']['median']:.3f} ms/step, "
      f"median {s['linear_iterations']['median_per_step']:.0f} PCG iterations/step, "
      f"final tip displacement ({tip[0]:.4f}, {tip[1]:.4f}, {tip[2]:.4f}) m")
PY
done

# The coupled mesh (paper Sec. 5): SOFA's liver (596 tets, from ../shared/data) driving its
# 2,194-vertex smooth surface; picture in out/coupled_liver.png.
liver=samples/coupled_liver/liver.json
if [ -f ../shared/data/meshes/sofa/liver.msh ]; then
  ./build/corofem run "$liver" --out out/coupled_liver --quiet
  /usr/bin/python3 samples/coupled_liver/plot_coupled.py --run out/coupled_liver --body liver --out out/coupled_liver.png
  /usr/bin/python3 -c "import json; s = json.load(open('out/coupled_liver/summary.json')); print('out/coupled_liver/summary.json: surface binding', s['bodies'][0]['surface'])"
  # An application's frame loop (samples/interactive): the liver dragged by a handle at 90 Hz,
  # pinned, released and pushed; its frames and per-frame times (median, 99th percentile).
  ./build/interactive --out out/interactive
  /usr/bin/python3 samples/interactive/plot_interactive.py out/interactive out/interactive.png
  # A renderer that lends its VkDevice to corofem and draws the liver straight from corofem's surface
  # buffer each frame (samples/renderer): PNG frames, checked against the surface's projection.
  if [ -x build/renderer ]; then
    LP_NUM_THREADS="${LP_NUM_THREADS:-0}" ./build/renderer --out out/renderer --png-every 5
    /usr/bin/python3 - <<'PY' || echo "out/renderer.png and .gif not made (Debian's Python lacks Pillow)"
import glob
from PIL import Image
names = sorted(glob.glob("out/renderer/frame_*.png"))
frames = [Image.open(f) for f in names]
# A strip of three frames at half size (the README's picture), and the animation in real time.
picks = [frames[len(frames) * k // 4 - 1] for k in (1, 2, 3)]
w, h = picks[0].width // 2, picks[0].height // 2
strip = Image.new("RGB", (3 * w, h))
for i, f in enumerate(picks):
    strip.paste(f.convert("RGB").resize((w, h), Image.LANCZOS), (i * w, 0))
strip.save("out/renderer.png")
gif = [f.convert("P", palette=Image.ADAPTIVE) for f in frames]
gif[0].save("out/renderer.gif", save_all=True, append_images=gif[1:], duration=83, loop=0)  # every 5th frame of 60 Hz
print(f"out/renderer.png: frames {', '.join(n[-8:-4] for n in [names[len(names) * k // 4 - 1] for k in (1, 2, 3)])}; out/renderer.gif: {len(frames)} frames")
PY
  fi
else
  echo "skipping the coupled-mesh and interactive samples: ../shared/data/meshes/sofa/liver.msh is absent"
fi
