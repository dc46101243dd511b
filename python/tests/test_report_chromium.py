"""The HTML session report rendered by headless Chromium.

Exit 0 pass, 1 fail, 77 skipped (only when no chromium binary is installed).
Writes the report and its screenshot next to the fixtures:
  $MANIP_PY_FIXTURES/report/report.html, report.png, group.html, group.png
"""
import os
import re
import shutil
import subprocess
import sys
import tempfile

import numpy as np

from manipplot import build as B
from manipplot.io import load_results

from . import fixtures as FX


def chromium():
    for name in ("chromium", "chromium-browser", "google-chrome"):
        p = shutil.which(name)
        if p:
            return p
    return None


def render(exe, html, png):
    prof = tempfile.mkdtemp(prefix="manipplot_chromium_")
    common = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--user-data-dir=" + prof,
              "--window-size=1200,3000"]
    url = "file://" + os.path.abspath(html)
    dom = subprocess.run(common + ["--dump-dom", url], capture_output=True, text=True, timeout=180)
    if dom.returncode != 0 or "<html" not in dom.stdout:
        raise AssertionError("chromium --dump-dom failed (%d): %s" % (dom.returncode, dom.stderr[-2000:]))
    if os.path.exists(png):
        os.remove(png)
    shot = subprocess.run(common + ["--screenshot=" + os.path.abspath(png), url], capture_output=True, text=True,
                          timeout=180)
    if shot.returncode != 0 or not os.path.exists(png):
        raise AssertionError("chromium --screenshot failed (%d): %s" % (shot.returncode, shot.stderr[-2000:]))
    shutil.rmtree(prof, ignore_errors=True)
    return dom.stdout


def check(dom, png, expected_figs, tables):
    fails = []
    imgs = re.findall(r"<img[^>]*data-figure=\"([^\"]+)\"[^>]*>", dom)
    if sorted(imgs) != sorted(expected_figs):
        fails.append("figures in DOM %s != expected %s" % (sorted(imgs), sorted(expected_figs)))
    m = re.search(r'data-images-decoded="(\d+)"', dom)
    if not m or int(m.group(1)) != len(expected_figs):
        fails.append("decoded images: %s of %d" % (m.group(1) if m else "none", len(expected_figs)))
    for cls in tables:
        if not re.search(r'<table class="%s"' % cls, dom):
            fails.append("table %s missing" % cls)
    import matplotlib.image as mpimg
    im = mpimg.imread(png)[..., :3]
    if im.shape[0] < 1000 or im.shape[1] < 1000:
        fails.append("screenshot too small: %s" % (im.shape,))
    if float(im.std()) < 0.05:
        fails.append("screenshot nearly uniform (std %.4f)" % im.std())
    nonwhite = float(np.mean(np.any(im < 0.9, axis=2)))
    if nonwhite < 0.02:
        fails.append("screenshot nearly blank (%.3f non-white)" % nonwhite)
    colours = len(np.unique((im * 255).astype(np.uint8).reshape(-1, 3), axis=0))
    if colours < 50:
        fails.append("screenshot has only %d colours" % colours)
    return fails


def main():
    exe = chromium()
    if exe is None:
        print("SKIP: no chromium binary (apt-get install chromium; scripts/setup.sh installs it)")
        return 77
    FX.require(FX.S_LCM, FX.S_JSON, FX.S_SIG, *FX.GROUP_JSON)
    out = os.path.join(FX.ROOT, "report")
    os.makedirs(out, exist_ok=True)
    fails = []
    # Session report.
    html = os.path.join(out, "report.html")
    r = subprocess.run([sys.executable, "-m", "manipplot.report", FX.S_JSON, "--signals", FX.S_SIG, "--log", FX.S_LCM,
                        "-o", html], capture_output=True, text=True)
    if r.returncode != 0:
        print(r.stderr)
        return 1
    res = load_results(FX.S_JSON)
    inp = B.resolve_inputs(res, FX.S_SIG, FX.S_LCM, load_logs=False)[0]
    expected = ["fig3_psd_jerk_x2", "fig4_nrmse", "fig5_trial_%d" % min(inp.signals)]
    s = res.sessions[0]
    expected += ["directional_%s" % m for m in s.methods() if s.per_angle(m)]
    expected += ["table1_%s" % m for m in s.methods() if s.summary(m) is not None]
    dom = render(exe, html, os.path.join(out, "report.png"))
    fails += ["session report: " + f for f in check(dom, os.path.join(out, "report.png"), expected,
                                                    ["table1", "directional", "settings", "info"])]
    for text in ("Excluded trials", "Warnings", "Settings used", "default, recommended", "BIASED"):
        if text not in dom:
            fails.append("session report: %r missing" % text)
    # Group report (five participants, no signals or logs: tables and per-angle/Table-1 figures).
    ghtml = os.path.join(out, "group.html")
    r = subprocess.run([sys.executable, "-m", "manipplot.report"] + FX.GROUP_JSON + ["-o", ghtml],
                       capture_output=True, text=True)
    if r.returncode not in (0, 1):
        print(r.stderr)
        return 1
    gexp = []
    for p in FX.GROUP_JSON:
        gs = load_results(p).sessions[0]
        if gs.psd.get("f_hz"):  # estimate_impedance's JSON carries the PSD arrays: Fig. 3 without the log
            gexp.append("fig3_psd_jerk_x2")
        gexp += ["directional_%s" % m for m in gs.methods() if gs.per_angle(m)]
        gexp += ["table1_%s" % m for m in gs.methods() if gs.summary(m) is not None]
    gdom = render(exe, ghtml, os.path.join(out, "group.png"))
    fails += ["group report: " + f for f in check(gdom, os.path.join(out, "group.png"), gexp, ["group", "table1"])]
    if "mean (std), n = 5" not in gdom:
        fails.append("group report: no 'mean (std), n = 5' row")
    # Control: a page whose figure does not decode and which has no table must be caught by the same checks.
    bad = os.path.join(out, "control_broken.html")
    with open(bad, "w") as f:
        f.write("<!DOCTYPE html><html><body><p>x</p><img data-figure=\"fig3_psd_jerk_x2\" src=\"data:image/png;base64,AAAA\">"
                "<script>window.addEventListener('load',function(){var n=0;for(var i=0;i<document.images.length;i++)"
                "{if(document.images[i].naturalWidth>0)n++;}document.body.setAttribute('data-images-decoded',n);});"
                "</script></body></html>")
    cdom = render(exe, bad, os.path.join(out, "control_broken.png"))
    cf = check(cdom, os.path.join(out, "control_broken.png"), ["fig3_psd_jerk_x2"], ["table1"])
    want = ("decoded images", "table table1 missing", "nearly uniform")
    if not all(any(w in f for f in cf) for w in want):
        fails.append("control page not caught by the checks: %s" % cf)
    for f in fails:
        print("FAIL:", f)
    print("report: %s\nscreenshot: %s\ngroup report: %s\ngroup screenshot: %s"
          % (html, os.path.join(out, "report.png"), ghtml, os.path.join(out, "group.png")))
    return 1 if fails else 0


if __name__ == "__main__":
    sys.exit(main())
