"""Regenerate docs/img/ from the ctest fixtures (run `ctest -R python:` first).

    PYTHONPATH=python:build/python .venv/bin/python python/tools/make_doc_images.py [FIXTURES_DIR]

PNGs at 130 dpi (each < 100 KB); the report screenshot is the test's Chromium
screenshot, cropped, reduced and palette-quantised.
"""
import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
SRC = os.path.normpath(os.path.join(HERE, "..", ".."))
IMG = os.path.join(SRC, "docs", "img")


def main(fix):
    s = os.path.join(fix, "session")
    tmp = tempfile.mkdtemp()
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([os.path.join(SRC, "python"), os.path.join(SRC, "build", "python"),
                                         env.get("PYTHONPATH", "")])
    subprocess.run([sys.executable, "-m", "manipplot.plots", os.path.join(s, "s.json"), "--signals",
                    os.path.join(s, "sig"), "--log", os.path.join(s, "s.lcm"), "-o", tmp, "--format", "png",
                    "--dpi", "130", "--method", "pem"], check=True, stdout=subprocess.DEVNULL, env=env)
    os.makedirs(IMG, exist_ok=True)
    first5 = sorted(f for f in os.listdir(tmp) if f.startswith("fig5_trial_"))[0]
    for src, dst in (("fig3_psd_jerk_x2.png", None), ("fig4_nrmse.png", None), (first5, "fig5_trial.png"),
                     ("directional_pem.png", None), ("table1_pem.png", None)):
        shutil.copy(os.path.join(tmp, src), os.path.join(IMG, dst or src))
    from PIL import Image
    im = Image.open(os.path.join(fix, "report", "report.png")).convert("RGB")
    im = im.crop((0, 0, 1200, 1800)).resize((700, 1050), Image.LANCZOS).quantize(colors=64, method=Image.FASTOCTREE)
    im.save(os.path.join(IMG, "report_screenshot.png"), optimize=True)
    for f in sorted(os.listdir(IMG)):
        size = os.path.getsize(os.path.join(IMG, f))
        print("%s %d bytes%s" % (f, size, "  (> 100 KB!)" if size > 100_000 else ""))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.join(SRC, "build", "python_fixtures"))
