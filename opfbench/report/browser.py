"""Headless Chromium driver for the report: open a page with the network refused, report
what happened (console errors, plots drawn, sections, requests), and take full-page
screenshots. Uses the Debian `chromium` binary only (`--dump-dom`, `--screenshot`); no
browser is downloaded.

Network: every request is sent to a local counting proxy that answers 403, and host names
resolve to nothing; the proxy's log is the list of requests that tried to leave the page.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import tempfile
import threading
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import urlsplit

from opfbench.errors import InputError

CANDIDATES = ("chromium", "chromium-browser", "google-chrome")
BROWSER_DOMAINS = ("google.com", "googleapis.com", "googleusercontent.com", "gvt1.com", "gstatic.com")
"""Domains of the services headless Chromium contacts on its own whatever page is open
(accounts, component updater, network time, variations; which hosts varies by version:
Debian's Chromium 150 opens www.google.com and android.clients.google.com with an empty
page). Their requests are not the page's (they still hit the refusing proxy); the page's
own resources are checked from inside it (`PageCheck.resources`)."""
VIRTUAL_TIME_MS = 20000
_PROBE = """<script>
window.__probe = {errors: []};
window.addEventListener("error", function (e) { __probe.errors.push("error: " + (e.message || e)); });
window.addEventListener("unhandledrejection", function (e) { __probe.errors.push("unhandled rejection: " + e.reason); });
(function () { var original = console.error; console.error = function () {
  __probe.errors.push(Array.prototype.map.call(arguments, String).join(" ")); return original.apply(console, arguments); }; })();
window.addEventListener("load", function () { setTimeout(function () {
  var plots = document.querySelectorAll("div.plot");
  var drawn = Array.prototype.filter.call(plots, function (d) {
    return d.classList.contains("js-plotly-plot") && d.querySelector("svg.main-svg") !== null; }).length;
  var out = {errors: __probe.errors, plots: plots.length, drawn: drawn,
             sections: Array.prototype.map.call(document.querySelectorAll("section"), function (s) { return s.id; }),
             resources: performance.getEntriesByType("resource").map(function (r) { return r.name; }),
             images: document.querySelectorAll("img").length,
             height: Math.ceil(document.documentElement.scrollHeight)};
  var pre = document.createElement("pre"); pre.id = "opfbench-probe"; pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre); }, 1000); });
</script>"""


@dataclass(frozen=True)
class PageCheck:
    """What the page did in the browser: errors (console.error, uncaught errors), number of
    plot containers and of drawn Plotly plots, section ids, resources it loaded, requests
    that reached the network (the proxy), full page height (px), <img> elements."""

    errors: list[str]
    plots: int
    drawn: int
    sections: list[str]
    resources: list[str]
    requests: list[str]
    height: int
    images: int

    @property
    def page_requests(self) -> list[str]:
        """Requests that reached the network and are not the browser's own service traffic."""
        return [r for r in self.requests if not _browser_service(_host(r))]


def _browser_service(host: str) -> bool:
    return any(host == d or host.endswith("." + d) for d in BROWSER_DOMAINS)


def _host(request_line: str) -> str:
    """Host of a proxy request line: "CONNECT host:443 HTTP/1.1" or "GET http://host/... HTTP/1.1"."""
    target = request_line.split(" ")[1] if " " in request_line else request_line
    return (urlsplit(target).hostname if "://" in target else target.rsplit(":", 1)[0]) or ""


def find_chromium() -> str | None:
    """Path of the Chromium binary ($OPFBENCH_CHROMIUM, else the first of CANDIDATES on PATH)."""
    given = os.environ.get("OPFBENCH_CHROMIUM")
    if given:
        return given if Path(given).is_file() else None
    return next((p for p in (shutil.which(c) for c in CANDIDATES) if p), None)


class _Proxy(ThreadingHTTPServer):
    def __init__(self) -> None:
        self.seen: list[str] = []
        super().__init__(("127.0.0.1", 0), _Refuse)


class _Refuse(BaseHTTPRequestHandler):
    def _refuse(self) -> None:
        self.server.seen.append(self.requestline)  # type: ignore[attr-defined]
        self.send_error(403, "network access refused by the opfbench report check")

    do_GET = do_POST = do_HEAD = do_CONNECT = do_PUT = do_OPTIONS = _refuse

    def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - the base class's name
        pass


def _run(binary: str, args: list[str], proxy: _Proxy, profile: str, timeout_s: float) -> str:
    flags = [
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        "--no-first-run",
        "--no-default-browser-check",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-extensions",
        "--disable-default-apps",
        "--disable-domain-reliability",
        "--no-pings",
        "--metrics-recording-only",
        "--disable-dev-shm-usage",
        "--disable-client-side-phishing-detection",
        "--safebrowsing-disable-auto-update",
        "--disable-breakpad",
        "--disable-component-extensions-with-background-pages",
        "--password-store=basic",
        "--disable-features=OptimizationHints,OptimizationGuideModelDownloading,OptimizationHintsFetching,"
        "OptimizationTargetPrediction,MediaRouter,DialMediaRouteProvider,Translate,AutofillServerCommunication,"
        "CertificateTransparencyComponentUpdater,NetworkTimeServiceQuerying,InterestFeedContentSuggestions,"
        "PrivacySandboxSettings4,AccountConsistency,SignInProfileCreation",
        "--allow-pre-commit-input",
        f"--user-data-dir={profile}",
        f"--proxy-server=http://127.0.0.1:{proxy.server_address[1]}",
        "--proxy-bypass-list=<-loopback>",
        "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1",
        f"--virtual-time-budget={VIRTUAL_TIME_MS}",
        "--run-all-compositor-stages-before-draw",
    ]
    done = subprocess.run([binary, *flags, *args], capture_output=True, text=True, timeout=timeout_s, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"{binary} exited with {done.returncode}: {done.stderr[-2000:]}")
    return done.stdout


def _with_proxy(fn):
    def wrapper(*args, **kwargs):
        proxy = _Proxy()
        thread = threading.Thread(target=proxy.serve_forever, daemon=True)
        thread.start()
        try:
            with tempfile.TemporaryDirectory(prefix="opfbench-chromium-") as profile:
                return fn(*args, proxy=proxy, profile=profile, **kwargs)
        finally:
            proxy.shutdown()
            proxy.server_close()

    return wrapper


def _binary() -> str:
    binary = find_chromium()
    if binary is None:
        raise InputError("no Chromium binary: install the Debian package `chromium` (apt-get install chromium)")
    return binary


@_with_proxy
def check_page(html: str | Path, width: int = 1400, *, proxy: _Proxy, profile: str, timeout_s: float = 180) -> PageCheck:
    """Open `html` (a file) in a `width` px wide headless Chromium with the network refused; see `PageCheck`.
    A copy of the page with a probe script is opened; the page itself is not changed."""
    text = Path(html).read_text(encoding="utf-8")
    if "<head>" not in text:
        raise InputError(f"{html} has no <head>: not an opfbench page")
    with tempfile.TemporaryDirectory(prefix="opfbench-probe-") as folder:
        probed = Path(folder) / "page.html"
        probed.write_text(text.replace("<head>", "<head>\n" + _PROBE, 1), encoding="utf-8")
        dom = _run(_binary(), [f"--window-size={width},1000", "--dump-dom", probed.as_uri()], proxy, profile, timeout_s)
    found = re.search(r'<pre id="opfbench-probe">(.*?)</pre>', dom, re.S)
    if found is None:
        raise RuntimeError("the probe did not run: the page never finished loading")
    data = json.loads(found.group(1).replace("&quot;", '"').replace("&lt;", "<").replace("&gt;", ">").replace("&amp;", "&"))
    return PageCheck(
        data["errors"],
        data["plots"],
        data["drawn"],
        data["sections"],
        data["resources"],
        list(proxy.seen),
        int(data["height"]),
        int(data["images"]),
    )


@_with_proxy
def _screenshot(html: Path, png: Path, width: int, height: int, *, proxy: _Proxy, profile: str) -> None:
    _run(_binary(), [f"--screenshot={png}", f"--window-size={width},{height}", html.resolve().as_uri()], proxy, profile, 300)


def screenshot(html: str | Path, png: str | Path, width: int = 1400, max_height: int = 30000) -> Path:
    """Full-page PNG of `html` (the page's height, at most `max_height` px) at `width` px,
    stored with an adaptive 256-colour palette (a third of the size; Pillow comes with matplotlib)."""
    from PIL import Image

    height = min(check_page(html, width).height, max_height)
    png = Path(png).resolve()
    png.parent.mkdir(parents=True, exist_ok=True)
    try:
        _screenshot(Path(html), png, width, height)
    except subprocess.TimeoutExpired:  # headless Chromium now and then hangs drawing a very tall page: once more
        _screenshot(Path(html), png, width, height)
    with Image.open(png) as image:
        small = image.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    small.save(png, optimize=True)
    return png
