"""Check the built documentation site as a reader sees it.

    python docs/check_site.py [docs/_build/html] [--shots DIR] [--no-browser]

1. **Links.** Every internal link (``href``) and every embedded resource (``src``, style
   sheets) of every HTML page of the site must point to a file of the site, and every
   ``#anchor`` to an ``id`` (or ``name``) in the page it names. A page may not load anything
   from the network (scripts, style sheets, images, fonts by URL): the site must work offline.
2. **Browser** (where Chromium is installed: ``chromium``, ``chromium-browser`` or
   ``$CHROMIUM``). The main pages are opened headless through the DevTools protocol, with
   every host name unresolvable (offline); a page fails on a JavaScript exception or console
   error, on a raw ``\\[``, ``\\(`` or ``$$`` left in its text after MathJax ran, on math that
   MathJax did not typeset, or on an image that did not load. With ``--shots DIR`` each main
   page's screenshot is written there. Without Chromium this part is skipped (said on stdout).
   A page also fails on reST or MyST markup left unrendered in its prose (``.. list-table::``,
   ``:math:`...```, ``{doc}`...```).

Exit status 0 when every check passes, 1 otherwise. Python's standard library only.
"""

from __future__ import annotations

import argparse
import base64
import html.parser
import json
import os
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from pathlib import Path

#: the pages opened in the browser (relative to the site root); a missing one is an error
MAIN_PAGES = (
    "index.html",
    "install.html",
    "getting_started.html",
    "user_guide/physics.html",
    "user_guide/stages.html",
    "user_guide/real_data.html",
    "user_guide/gpu.html",
    "user_guide/sweeps.html",
    "reference.html",
    "architecture.html",
    "reading.html",
    "model.html",
    "cli.html",
    "outputs.html",
    "api/index.html",
    "api/top.html",
    "api/pipeline.html",
    "auto_examples/index.html",
    "auto_examples/01_start/plot_02_psst_vs_conventional.html",
    "reproduction.html",
    "citing.html",
    "changelog.html",
)

#: extra screenshots (with --shots) scrolled to a section: (page, anchor)
SECTION_SHOTS = (
    ("api/top.html", "config-keys"),
    ("api/top.html", "result-attributes"),
    ("cli.html", "cli-run"),
    ("outputs.html", "metrics-keys"),
    ("user_guide/physics.html", "its-correlation"),
    ("user_guide/physics.html", "the-cube-of-slices"),
    ("reproduction.html", "fig-4-code-length-qcr-and-the-conventional-lidar"),
    ("auto_examples/index.html", "scale-and-the-detector"),
)


# -- 1. links and anchors -----------------------------------------------------------------
class _Page(html.parser.HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.ids: set[str] = set()
        self.links: list[tuple[str, str]] = []  # (attribute, url)

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for key in ("id", "name") if tag in ("a", "span", "div", "section", "dt", "p",
                                                 "table", "img", "figure", "h1", "h2", "h3",
                                                 "h4", "h5", "h6", "li", "dl", "dd", "tr",
                                                 "td", "th", "pre", "code", "svg", "nav",
                                                 "article", "main", "aside", "ul", "ol",
                                                 "input", "label", "button", "details",
                                                 "summary", "caption", "em", "strong",
                                                 "header", "footer", "form", "object",
                                                 "iframe", "blockquote", "colgroup", "col",
                                                 "tbody", "thead") else ("id",):
            if a.get(key):
                self.ids.add(a[key])
        if tag == "a" and a.get("href") is not None:
            self.links.append(("href", a["href"]))
        elif tag == "link" and a.get("href") and "stylesheet" in (a.get("rel") or ""):
            self.links.append(("stylesheet", a["href"]))
        elif tag in ("img", "script", "iframe", "source", "video", "audio", "embed") \
                and a.get("src"):
            self.links.append(("src", a["src"]))


def _is_remote(url: str) -> bool:
    return url.startswith(("http://", "https://", "//", "ftp://"))


def check_links(root: Path) -> list[str]:
    pages = {p: None for p in sorted(root.rglob("*.html"))
             if "_downloads" not in p.parts and "_static" not in p.parts
             and "_sources" not in p.parts}
    parsed: dict[Path, _Page] = {}

    def parse(path: Path) -> _Page:
        if path not in parsed:
            page = _Page()
            page.feed(path.read_text(encoding="utf-8", errors="replace"))
            parsed[path] = page
        return parsed[path]

    errors = []
    n_links = 0
    for page_path in pages:
        page = parse(page_path)
        rel = page_path.relative_to(root)
        for kind, url in page.links:
            if url.startswith(("mailto:", "javascript:", "data:", "tel:")):
                continue
            if _is_remote(url):
                if kind != "href":
                    errors.append(f"{rel}: loads {url} from the network (the site must work "
                                  "offline)")
                continue
            n_links += 1
            parts = urllib.parse.urlsplit(url)
            target = page_path if not parts.path else \
                (page_path.parent / urllib.parse.unquote(parts.path)).resolve()
            if target.is_dir():
                target = target / "index.html"
            if not target.exists():
                errors.append(f"{rel}: broken link {url}")
                continue
            frag = urllib.parse.unquote(parts.fragment)
            if frag and target.suffix == ".html":
                if frag not in parse(target).ids:
                    errors.append(f"{rel}: anchor #{frag} not found in {target.name} "
                                  f"(link {url})")
    print(f"links: {len(pages)} pages, {n_links} internal links and resources checked, "
          f"{len(errors)} broken")
    return errors


# -- 2. the browser -------------------------------------------------------------------------
class _WebSocket:
    """A minimal WebSocket client (RFC 6455, text frames) for the DevTools protocol."""

    def __init__(self, url: str, timeout: float = 60.0):
        parts = urllib.parse.urlsplit(url)
        self.sock = socket.create_connection((parts.hostname, parts.port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        request = (f"GET {parts.path} HTTP/1.1\r\nHost: {parts.hostname}:{parts.port}\r\n"
                   "Upgrade: websocket\r\nConnection: Upgrade\r\n"
                   f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n")
        self.sock.sendall(request.encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("the browser closed the DevTools connection")
            head += chunk
        head, _, self.buffer = head.partition(b"\r\n\r\n")
        if b" 101 " not in head.split(b"\r\n")[0]:
            raise ConnectionError(f"DevTools handshake failed: {head[:200]!r}")

    def _read(self, n: int) -> bytes:
        while len(self.buffer) < n:
            chunk = self.sock.recv(1 << 16)
            if not chunk:
                raise ConnectionError("the browser closed the DevTools connection")
            self.buffer += chunk
        out, self.buffer = self.buffer[:n], self.buffer[n:]
        return out

    def send(self, text: str) -> None:
        data = text.encode()
        head = bytearray([0x81])
        if len(data) < 126:
            head.append(0x80 | len(data))
        elif len(data) < 1 << 16:
            head.append(0x80 | 126)
            head += struct.pack(">H", len(data))
        else:
            head.append(0x80 | 127)
            head += struct.pack(">Q", len(data))
        mask = os.urandom(4)
        self.sock.sendall(bytes(head) + mask + bytes(b ^ mask[i % 4] for i, b in
                                                   enumerate(data)))

    def recv(self) -> str:
        message = b""
        while True:
            b0, b1 = self._read(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._read(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._read(8))[0]
            payload = self._read(n)
            opcode = b0 & 0x0F
            if opcode == 0x8:
                raise ConnectionError("the browser closed the DevTools connection")
            if opcode in (0x9, 0xA):  # ping / pong: ignore
                continue
            message += payload
            if b0 & 0x80:
                return message.decode("utf-8", errors="replace")


class _Browser:
    def __init__(self, exe: str):
        self.profile = tempfile.mkdtemp(prefix="spslidar-chromium-")
        self.proc = subprocess.Popen(
            [exe, "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run",
             "--disable-dev-shm-usage", "--remote-debugging-port=0",
             "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
             "--allow-file-access-from-files", f"--user-data-dir={self.profile}",
             "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        port = None
        while time.monotonic() < deadline and port is None:
            line = self.proc.stderr.readline()
            if not line and self.proc.poll() is not None:
                break
            if "DevTools listening on" in line:
                port = urllib.parse.urlsplit(line.split("on", 1)[1].strip()).port
        if port is None:
            self.close()
            raise RuntimeError("Chromium did not start its DevTools endpoint")
        req = urllib.request.Request(f"http://127.0.0.1:{port}/json/new?about:blank",
                                     method="PUT")
        with urllib.request.urlopen(req, timeout=30) as resp:
            target = json.load(resp)
        self.ws = _WebSocket(target["webSocketDebuggerUrl"])
        self.next_id = 0
        self.events: list[dict] = []
        for method in ("Page.enable", "Runtime.enable", "Log.enable"):
            self.call(method)
        self.call("Emulation.setDeviceMetricsOverride", width=1280, height=1000,
                  deviceScaleFactor=1, mobile=False)

    def call(self, method: str, **params):
        self.next_id += 1
        my_id = self.next_id
        self.ws.send(json.dumps({"id": my_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == my_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            if "method" in msg:
                self.events.append(msg)

    def wait_event(self, name: str, timeout: float = 60.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for i, ev in enumerate(self.events):
                if ev.get("method") == name:
                    del self.events[i]
                    return True
            self.ws.sock.settimeout(max(0.1, deadline - time.monotonic()))
            try:
                self.events.append(json.loads(self.ws.recv()))
            except TimeoutError:
                return False
        return False

    def evaluate(self, expression: str, await_promise: bool = False):
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True,
                           awaitPromise=await_promise)
        if "exceptionDetails" in result:
            raise RuntimeError(result["exceptionDetails"].get("text", "evaluation failed"))
        return result.get("result", {}).get("value")

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        shutil.rmtree(self.profile, ignore_errors=True)


#: run in the page once it has loaded: waits for MathJax, then reports what a reader sees
_PAGE_CHECK = r"""
(async () => {
  if (window.MathJax && MathJax.startup && MathJax.startup.promise) {
    await MathJax.startup.promise;
  }
  await Promise.all(Array.from(document.images).map(img => img.complete ? null :
      new Promise(r => { img.onload = img.onerror = r; setTimeout(r, 10000); })));
  const main = document.querySelector("main") || document.body;
  const text = main.innerText;
  const raw = [];
  for (const pat of ["\\[", "\\(", "$$"]) {
    const at = text.indexOf(pat);
    if (at >= 0) raw.push(JSON.stringify(text.slice(Math.max(0, at - 30), at + 40)));
  }
  // markup that was not rendered (a directive parsed as the wrong language), outside code
  const prose = main.cloneNode(true);
  prose.querySelectorAll("pre, code, .highlight").forEach(e => e.remove());
  const proseText = prose.textContent;
  const markup = [".. list-table::", ":header-rows:", "```{", ".. autosummary::", ".. math::",
                  ":math:`", "{math}`", "{doc}`", ":doc:`", ":func:`", ":class:`"]
      .filter(m => proseText.includes(m));
  const untypeset = document.querySelectorAll(
      "div.math:not(:has(mjx-container)), span.math:not(:has(mjx-container))").length;
  const broken = Array.from(document.images)
      .filter(img => !(img.complete && img.naturalWidth > 0))
      .map(img => img.getAttribute("src"));
  return {raw: raw, untypeset: untypeset, broken: broken, markup: markup,
          mathjax: !!window.MathJax, math: document.querySelectorAll("mjx-container").length,
          images: document.images.length, title: document.title};
})()
"""


def _find_chromium() -> str | None:
    for name in (os.environ.get("CHROMIUM"), "chromium", "chromium-browser",
                 "google-chrome"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def check_browser(root: Path, shots: Path | None) -> list[str]:
    exe = _find_chromium()
    if exe is None:
        print("browser: Chromium not found, page checks skipped")
        return []
    errors = []
    browser = _Browser(exe)
    try:
        if shots is not None:
            shots.mkdir(parents=True, exist_ok=True)
        # the main pages, then every gallery example
        examples = sorted(str(p.relative_to(root))
                          for p in root.glob("auto_examples/*/plot_*.html"))
        for rel in (*MAIN_PAGES, *(e for e in examples if e not in MAIN_PAGES)):
            path = root / rel
            if not path.exists():
                errors.append(f"{rel}: main page missing")
                continue
            browser.events.clear()
            browser.call("Page.navigate", url=path.resolve().as_uri())
            if not browser.wait_event("Page.loadEventFired", 60):
                errors.append(f"{rel}: did not finish loading in 60 s")
                continue
            report = browser.evaluate(_PAGE_CHECK, await_promise=True)
            time.sleep(0.2)
            browser.wait_event("__drain__", 0.3)  # collect late console messages
            problems = []
            for ev in browser.events:
                if ev.get("method") == "Runtime.exceptionThrown":
                    d = ev["params"]["exceptionDetails"]
                    text = d.get("exception", {}).get("description") or d.get("text")
                    problems.append(f"JavaScript exception: {text}")
                elif ev.get("method") == "Log.entryAdded" \
                        and ev["params"]["entry"].get("level") == "error":
                    e = ev["params"]["entry"]
                    problems.append(f"console error: {e.get('text')} {e.get('url', '')}")
                elif ev.get("method") == "Runtime.consoleAPICalled" \
                        and ev["params"].get("type") == "error":
                    args = [a.get("value", a.get("description", ""))
                            for a in ev["params"].get("args", [])]
                    problems.append(f"console.error: {' '.join(map(str, args))}")
            if report["raw"]:
                problems.append(f"raw math left after MathJax: {', '.join(report['raw'])}")
            if report["markup"]:
                problems.append(f"markup left unrendered: {', '.join(report['markup'])}")
            if report["untypeset"]:
                problems.append(f"{report['untypeset']} math elements not typeset")
            if report["broken"]:
                problems.append(f"images not loaded: {', '.join(report['broken'])}")
            errors += [f"{rel}: {p}" for p in problems]
            print(f"browser: {rel}: {report['images']} images, {report['math']} formulas"
                  f"{'' if not problems else f', {len(problems)} problem(s)'}")
            if shots is not None and rel in MAIN_PAGES:
                shot = browser.call("Page.captureScreenshot", format="png")
                name = rel.replace("/", "_").replace(".html", ".png")
                (shots / name).write_bytes(base64.b64decode(shot["data"]))
        for rel, anchor in SECTION_SHOTS if shots is not None else ():
            browser.call("Page.navigate", url=(root / rel).resolve().as_uri())
            if not browser.wait_event("Page.loadEventFired", 60):
                continue
            found = browser.evaluate(
                "(async () => { if (window.MathJax && MathJax.startup) "
                "await MathJax.startup.promise; const e = document.getElementById("
                + json.dumps(anchor) + "); if (!e) return false; e.scrollIntoView(); "
                "window.scrollBy(0, -80); return true; })()", await_promise=True)
            if not found:
                errors.append(f"{rel}: no section #{anchor} to photograph")
                continue
            time.sleep(0.3)
            shot = browser.call("Page.captureScreenshot", format="png")
            name = rel.replace("/", "_").replace(".html", f"__{anchor}.png")
            (shots / name).write_bytes(base64.b64decode(shot["data"]))
    finally:
        browser.close()
    return errors


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("site", nargs="?", default=str(Path(__file__).parent / "_build" /
                                                       "html"),
                        help="the built HTML site (default docs/_build/html)")
    parser.add_argument("--shots", metavar="DIR", help="write screenshots of the main pages")
    parser.add_argument("--no-browser", action="store_true", help="links and anchors only")
    args = parser.parse_args(argv)
    root = Path(args.site)
    if not (root / "index.html").exists():
        print(f"check_site: no built site in {root} (build it first)", file=sys.stderr)
        return 1
    errors = check_links(root)
    if not args.no_browser:
        errors += check_browser(root, Path(args.shots) if args.shots else None)
    for e in errors:
        print(f"check_site: {e}", file=sys.stderr)
    print("check_site: " + ("OK" if not errors else f"{len(errors)} problem(s)"))
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
