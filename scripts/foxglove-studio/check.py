#!/usr/bin/env python3
"""Opens Foxglove Studio 1.48.0 in headless Chromium on one data source and reports what it shows.

Usage:
  check.py NAME --studio URL (--ws URL | --remote-file URL | --local-file PATH) --out DIR
           [--layout layout.json|layout-network.json|layout-map.json]
           [--publish | --publish-refused | --view-only]
           [--expect TOPIC,...]
           [--absent TOPIC,...] [--expect-delay] [--expect-drawn PCT] [--settle-s S]

The data source: --ws opens Studio on a Foxglove WebSocket server
(`?ds=foxglove-websocket&ds.url=...`); --remote-file opens an MCAP log by URL
(`?ds=remote-file&ds.url=...`, read with HTTP ranges); --local-file opens it as a local file,
through the file input Studio keeps for test drivers (`input[data-puppeteer-file-upload]`, what
a file dropped on the window goes through: McapLocalDataSourceFactory); a file is then seen
near its end (a click at 90 % of the playback bar). Studio's page comes
from --studio (serve.py), its layout from layout.json: 3D, Image (/camera/image), Plot
(/link/frames.delay_ms), Log (/session/log), Log (/link/log), Publish (/orders) and Teleop;
or from layout-network.json, for a network: 3D (both vehicles), Image (/vehicle/2/camera/image),
Plot (/network/frames.delay_ms), Log (/vehicle/1/link/log, /vehicle/2/link/log); or from
layout-map.json, for octo-delta's live map: 3D (/octo_delta/view, /octo_delta/vehicle in frame
map), Log (/octo_delta/log).

Each of these is a failure:
- an entry of the data source's Problems list (its message, and what its dialog says);
- an error in a panel's settings (the error icon of any node of any panel's settings tree,
  with its tooltip's text; every node is expanded to find them), except `Topic T is not
  available` for a topic of --absent (the layout's /session/log panel on a log file, which has
  no /session/log: it is live only), which is listed as expected;
- a console error or an uncaught page error;
- a blank: a topic of --expect with no message counted in the Topics list, the Image panel
  still waiting for an image, with --expect-delay a Plot with no value of delay_ms, with
  --expect-drawn PCT a 3D panel less than PCT % of which is in the colours of octo-delta's map
  (red: its voxels near 0 m are; needs Pillow), still so --within-s (120) after the first
  --settle-s (15) of watching;
- with --publish: the Publish panel's GoTo not enabled, or no `order N acknowledged` in the
  /session/log panel within 45 s of sending it;
- with --publish-refused (a URL without the control token): an `order N acknowledged` within
  15 s of sending the GoTo, or no `publishing refused` entry in the Problems list (that entry is
  expected, and listed as such);
- with --view-only (a URL without the control token, nothing sent): none more; a `publishing
  refused` entry, which the server may list when Studio's 3D panel advertises its channels (it
  does so on its own), is expected and listed as such.

Writes DIR/NAME.png (the window), DIR/NAME-3d.png and DIR/NAME.json (everything seen, warnings
too). Prints one line per failure; exits 0 when there is none, 1 when there is one, 2 when the
check could not be made (Studio did not start, the data source never showed topics).
"""

import argparse
import io
import json
import re
import sys
import time
from pathlib import Path
from urllib.parse import quote

from playwright.sync_api import Error as PlaywrightError
from playwright.sync_api import TimeoutError as PlaywrightTimeout
from playwright.sync_api import sync_playwright

CHROMIUM = "/usr/bin/chromium"
# WebGL for the 3D panel without a GPU: SwiftShader, which recent Chromium enables only on
# request.
CHROMIUM_ARGS = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--ignore-gpu-blocklist"]
VIEWPORT = {"width": 1600, "height": 1000}
# How long a click or a screenshot may wait for the page: drawing in software WebGL holds it for
# seconds at a time (octo-delta's map, redrawn whole at each of its messages: half a minute and
# more on two busy cores).
ACTION_TIMEOUT_MS = 120_000

# Names for the panels of the layouts, by their ids (layout.json, layout-network.json,
# layout-map.json).
PANEL_NAMES = {
    "3D!rov": "3D",
    "ImageViewPanel!camera": "Image",
    "Plot!delay": "Plot",
    "RosOut!session": "Log /session/log",
    "RosOut!link": "Log /link/log",
    "RosOut!vehicle1": "Log /vehicle/1/link/log",
    "RosOut!vehicle2": "Log /vehicle/2/link/log",
    "3D!map": "3D",
    "RosOut!map": "Log /octo_delta/log",
    "Publish!goto": "Publish",
    "Teleop!joystick": "Teleop",
}
PANELS = {}  # the panels of the layout in use: id -> name
ACKNOWLEDGED = re.compile(r"order \d+ acknowledged")


class Setup(Exception):
    """The check could not be made: exit code 2."""


class Findings:
    """What the viewer showed, gathered from the console and the page."""

    def __init__(self, name):
        self.name = name
        self.started = time.monotonic()
        self.console_errors = []
        self.console_warnings = []
        self.page_errors = []
        self.problems = []
        self.expected_problems = []
        self.panel_errors = []
        self.expected_errors = []
        self.blank = []
        self.counts = {}
        self.publish = None
        self.ready_s = None
        self.drawn_pct = None

    def at(self):
        return round(time.monotonic() - self.started, 1)

    def on_console(self, message):
        seen = {"t_s": self.at(), "text": message.text}
        if message.location and message.location.get("url"):
            seen["url"] = message.location["url"]
        if message.type == "error":
            self.console_errors.append(seen)
        elif message.type == "warning":
            self.console_warnings.append(seen)

    def on_page_error(self, error):
        self.page_errors.append({"t_s": self.at(), "text": str(error)})

    def failures(self):
        """One line per failure."""
        lines = []
        for problem in self.problems:
            details = problem["details"][:300] + ("..." if len(problem["details"]) > 300 else "")
            lines.append(f"problem: {problem['message']}" + (f" [{details}]" if details else ""))
        lines += [f"panel {e['panel']}: {e['node']}: {e['error']}" for e in self.panel_errors]
        lines += [f"console error{repeated(n)}: {text}" for text, n in tally(self.console_errors)]
        lines += [f"page error{repeated(n)}: {text}" for text, n in tally(self.page_errors)]
        lines += [f"blank: {b}" for b in self.blank]
        if self.publish is not None and "error" in self.publish:
            lines.append(f"publish: {self.publish['error']}")
        return lines

    def as_json(self):
        return {
            "name": self.name,
            "failures": self.failures(),
            "problems": self.problems,
            "expected_problems": self.expected_problems,
            "panel_errors": self.panel_errors,
            "expected_panel_errors": self.expected_errors,
            "console_errors": self.console_errors,
            "page_errors": self.page_errors,
            "blank": self.blank,
            "topic_counts": self.counts,
            "publish": self.publish,
            "ready_s": self.ready_s,
            "drawn_pct": self.drawn_pct,
            "console_warnings": self.console_warnings,
        }


def tally(seen):
    """(text, how many times) for each text of `seen`, in the order first seen."""
    counts = {}
    for item in seen:
        counts[item["text"]] = counts.get(item["text"], 0) + 1
    return list(counts.items())


def repeated(times):
    return f" (x{times})" if times > 1 else ""


def wait_for(condition, seconds, what):
    """Polls `condition` until it returns something truthy, and returns that; Setup after `seconds`."""
    deadline = time.monotonic() + seconds
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise Setup(f"{what}: not seen within {seconds} s")
        time.sleep(0.25)


def panel(page, panel_id):
    """The layout's panel `panel_id`."""
    return page.locator(f'[data-testid="panel-mouseenter-container {panel_id}"]')


def show_data_source(page):
    """Shows the left sidebar's data source view (a panel's settings replace it)."""
    if page.get_by_role("tab", name=re.compile("^Problems")).count() == 0:
        page.locator("[data-sidebar-key=connection]").click()
        page.get_by_role("tab", name=re.compile("^Problems")).wait_for(timeout=5000)


def topic_counts(page):
    """The Topics list: topic name -> message count (0 for '—')."""
    show_data_source(page)
    page.get_by_role("tab", name="Topics").click()
    counts = {}
    for cell in page.locator("[data-topic-stat=count]").all():
        text = cell.inner_text().strip().replace(",", "")
        counts[cell.get_attribute("data-topic")] = int(text) if text.isdigit() else 0
    return counts


def read_problems(page, findings):
    """Reads the Problems list, and what each entry's dialog says."""
    show_data_source(page)
    page.get_by_role("tab", name=re.compile("^Problems")).click()
    listing = page.locator("li .MuiListItemButton-root")
    wait_for(
        lambda: page.get_by_text("No problems found", exact=True).count() > 0 or listing.count() > 0,
        5,
        "the Problems list",
    )
    for index in range(listing.count()):
        item = listing.nth(index)
        message = " ".join(item.inner_text().split())
        details = ""
        try:
            item.click()
            dialog = page.get_by_role("dialog")
            dialog.wait_for(timeout=3000)
            details = " ".join(dialog.inner_text().split())
            page.keyboard.press("Escape")
            dialog.wait_for(state="detached", timeout=3000)
        except PlaywrightError as error:
            details = f"(its dialog was not read: {error.message.splitlines()[0]})"
        findings.problems.append({"message": message, "details": details})
    page.get_by_role("tab", name="Topics").click()


def read_panel_errors(page, findings, panel_id, absent):
    """Opens the panel's settings, expands every node, reads every error icon's tooltip."""
    container = panel(page, panel_id)
    container.hover()
    container.locator("button:has([data-testid=SettingsIcon])").first.click()
    heading = page.get_by_role("heading", name=re.compile("panel settings$", re.I))
    heading.wait_for(timeout=5000)
    # The sidebar is a tile of the app's own mosaic, beside the one holding the layout.
    sidebar = page.locator(".mosaic-tile").filter(has=heading).filter(has_not=page.locator(".mosaic-window"))
    if sidebar.count() != 1:
        raise Setup(f"panel {PANELS[panel_id]}: its settings sidebar not found")
    for _ in range(50):  # expand every collapsed node; each click may reveal more
        collapsed = sidebar.locator("[data-testid=ArrowRightIcon]")
        if collapsed.count() == 0:
            break
        collapsed.first.click()
    icons = sidebar.locator("[data-testid=ErrorIcon]")
    for index in range(icons.count()):
        icon = icons.nth(index)
        node = icon.evaluate(
            """(el) => {
                 let row = el.parentElement;
                 while (row && !row.innerText.trim()) row = row.parentElement;
                 return row ? row.innerText.trim().split('\\n')[0] : '';
               }"""
        )
        icon.hover()
        tooltip = page.get_by_role("tooltip").last
        try:
            tooltip.wait_for(timeout=2000)
            error = " ".join(tooltip.inner_text().split())
        except PlaywrightTimeout:
            error = "(an error icon without a tooltip)"
        seen = {"panel": PANELS[panel_id], "node": node, "error": error}
        if any(error == f"Topic {topic} is not available" for topic in absent):
            findings.expected_errors.append(seen)
        else:
            findings.panel_errors.append(seen)
        page.mouse.move(VIEWPORT["width"] - 5, VIEWPORT["height"] - 5)


def three_d():
    """The id of the layout's 3D panel."""
    return next(panel_id for panel_id in PANELS if panel_id.startswith("3D!"))


def session_log(page):
    """The text of the /session/log panel."""
    return panel(page, "RosOut!session").inner_text()


def click_goto(page, findings):
    """Clicks the Publish panel's button once it is enabled: the acknowledgements seen before,
    or None (and the failure noted) if it never was."""
    button = panel(page, "Publish!goto").get_by_role("button", name="Send GoTo")
    try:
        wait_for(button.is_enabled, 20, "the Publish panel's button enabled")
    except Setup as error:
        findings.publish = {"error": str(error)}
        return None
    before = set(ACKNOWLEDGED.findall(session_log(page)))
    button.click()
    findings.publish = {"sent_at_s": findings.at()}
    return before


def publish_goto(page, findings):
    """Clicks the Publish panel's button; waits for the order's acknowledgement on /session/log."""
    before = click_goto(page, findings)
    if before is None:
        return
    sent = time.monotonic()
    try:
        new = wait_for(lambda: set(ACKNOWLEDGED.findall(session_log(page))) - before, 45, "an acknowledgement")
        findings.publish.update(acknowledged=sorted(new)[0], after_s=round(time.monotonic() - sent, 1))
    except Setup:
        findings.publish["error"] = "GoTo sent, no 'order N acknowledged' on /session/log within 45 s"


def publish_refused(page, findings):
    """Clicks the Publish panel's button on a view without the token: nothing may be acknowledged."""
    before = click_goto(page, findings)
    if before is None:
        return
    page.wait_for_timeout(15000)
    new = set(ACKNOWLEDGED.findall(session_log(page))) - before
    if new:
        findings.publish["error"] = f"GoTo sent without the token, and {sorted(new)[0]}"
    else:
        findings.publish["refused"] = True


def drawn_share(page):
    """The share of the 3D panel's pixels in the map's colours: red (over green and blue by more
    than 60 of 255; octo-delta colours fine voxels by height, red at 0 m), which neither the
    light background, the blue grid, grey nor yellow is (tdma-run's panels, with their axes and
    yellow transform lines, have none at the quarter scale measured)."""
    from PIL import Image  # only with --expect-drawn (Pillow)

    shot = Image.open(io.BytesIO(panel(page, three_d()).screenshot())).convert("RGB")
    rgb = shot.reduce(4).tobytes()
    red = sum(1 for i in range(0, len(rgb), 3) if rgb[i] - max(rgb[i + 1], rgb[i + 2]) > 60)
    return red / (len(rgb) // 3)


def blanks(page, expect, expect_delay, expect_drawn=None):
    """What is still blank: (the Topics list's counts, one line per blank)."""
    counts = topic_counts(page)
    found = [f"{topic}: no message counted in the Topics list" for topic in expect if counts.get(topic, 0) == 0]
    if expect_drawn is not None:
        drawn_pct = 100 * drawn_share(page)
        if drawn_pct < expect_drawn:
            found.append(f"3D: the map not drawn ({drawn_pct:.2f} % of it in the map's colours,"
                         f" at least {expect_drawn} % expected)")
    image = panel(page, "ImageViewPanel!camera")
    if image.get_by_text("Waiting for images", exact=False).count() > 0:
        found.append(f"Image: still '{' '.join(image.inner_text().split())}'")
    if panel(page, three_d()).locator("canvas").count() == 0:
        found.append("3D: no canvas")
    if expect_delay:
        # With values in the legend, the Plot shows the latest delay_ms after the path.
        legend = panel(page, "Plot!delay").inner_text()
        if not re.search(r"delay_ms\s+[-\d.]+", legend):
            found.append("Plot: no value of delay_ms")
    return counts, found


def wait_for_data(page, expect, expect_delay, expect_drawn, seconds):
    """Waits, at most `seconds`, until nothing is blank (a session's first image takes a while)."""
    deadline = time.monotonic() + seconds
    while blanks(page, expect, expect_delay, expect_drawn)[1] and time.monotonic() < deadline:
        page.wait_for_timeout(1000)


def seek_near_end(page):
    """File sources: seek to 90 % of the log (a click on the playback bar's scrubber), so that
    the panels show its late messages (the first image comes half a minute in)."""
    box = page.evaluate(
        """() => {
             const wide = [...document.querySelectorAll('div')].filter((el) => {
               const r = el.getBoundingClientRect();
               return r.width > 0.7 * innerWidth && r.height > 0 && r.height < 40
                 && r.top > innerHeight - 140 && getComputedStyle(el).cursor === 'pointer';
             });
             if (wide.length === 0) return null;
             const r = wide[wide.length - 1].getBoundingClientRect();
             return {x: r.x, y: r.y, width: r.width, height: r.height};
           }"""
    )
    if box is None:
        raise Setup("the playback bar's scrubber: not found")
    page.mouse.click(box["x"] + box["width"] * 0.9, box["y"] + box["height"] / 2)


def run(args):
    findings = Findings(args.name)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    layout = json.loads((Path(__file__).parent / args.layout).read_text())
    PANELS.update({panel_id: PANEL_NAMES.get(panel_id, panel_id) for panel_id in layout["configById"]})
    if args.ws:
        # Encoded whole: the URL may carry the control token as its own query (?token=...).
        query = f"?ds=foxglove-websocket&ds.url={quote(args.ws, safe='')}&layout={args.layout}"
    elif args.remote_file:
        query = f"?ds=remote-file&ds.url={args.remote_file}&layout={args.layout}"
    else:
        query = f"?layout={args.layout}"
    with sync_playwright() as playwright:
        try:
            browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        except PlaywrightError as error:
            raise Setup(f"{CHROMIUM} did not start: {error.message.splitlines()[0]}")
        try:
            page = browser.new_context(viewport=VIEWPORT).new_page()
            page.set_default_timeout(ACTION_TIMEOUT_MS)
            page.on("console", findings.on_console)
            page.on("pageerror", findings.on_page_error)
            page.goto(args.studio.rstrip("/") + "/" + query)
            wait_for(lambda: page.get_by_role("tab", name=re.compile("^Problems")).count() > 0 or (
                page.locator("input[data-puppeteer-file-upload]").count() > 0 and args.local_file
            ), 120, "Studio's page")
            if args.local_file:
                page.keyboard.press("Escape")  # the welcome dialog
                page.set_input_files("input[data-puppeteer-file-upload]", args.local_file)
            wait_for(lambda: page.get_by_role("tab", name=re.compile("^Problems")).count() > 0, 30, "a data source")
            wait_for(lambda: len(topic_counts(page)) > 0, 60, "topics in the Topics list")
            findings.ready_s = findings.at()
            if not args.ws:
                page.wait_for_timeout(3000)
                seek_near_end(page)
            page.wait_for_timeout(int(args.settle_s * 1000))
            expect = [t for t in args.expect.split(",") if t]
            wait_for_data(page, expect, args.expect_delay, args.expect_drawn, args.within_s)
            if args.publish:
                publish_goto(page, findings)
            if args.publish_refused:
                publish_refused(page, findings)
            page.mouse.move(VIEWPORT["width"] - 5, VIEWPORT["height"] - 5)
            page.wait_for_timeout(1000)
            page.screenshot(path=str(out / f"{args.name}.png"))
            panel(page, three_d()).screenshot(path=str(out / f"{args.name}-3d.png"))
            findings.counts, findings.blank = blanks(page, expect, args.expect_delay, args.expect_drawn)
            if args.expect_drawn is not None:
                findings.drawn_pct = round(100 * drawn_share(page), 2)
            read_problems(page, findings)
            if args.publish_refused or args.view_only:
                refused = [p for p in findings.problems if "publishing refused" in p["message"]]
                findings.problems = [p for p in findings.problems if p not in refused]
                findings.expected_problems = refused
                if args.publish_refused and not refused:
                    findings.publish = {"error": "no 'publishing refused' in the Problems list"}
            for panel_id in PANELS:
                read_panel_errors(page, findings, panel_id, [t for t in args.absent.split(",") if t])
        except PlaywrightError as error:
            why = f"the page did not do what was expected: {error.message.splitlines()[0]}"
            try:
                page.screenshot(path=str(out / f"{args.name}-setup-failure.png"), timeout=10000)
            except PlaywrightError:
                why += " (and no screenshot of it could be taken)"
            raise Setup(why)
        finally:
            browser.close()
    (out / f"{args.name}.json").write_text(json.dumps(findings.as_json(), indent=2) + "\n")
    failures = findings.failures()
    for line in failures:
        print(f"{args.name}: {line}")
    if findings.publish and findings.publish.get("refused") and findings.expected_problems:
        print(f"{args.name}: GoTo from the Publish panel without the token: refused, Studio shows"
              f" {findings.expected_problems[0]['message']!r}")
    if args.view_only and findings.expected_problems:
        print(f"{args.name}: without the token, Studio lists (expected)"
              f" {findings.expected_problems[0]['message']!r}")
    if findings.publish and "acknowledged" in findings.publish:
        print(f"{args.name}: GoTo from the Publish panel: {findings.publish['acknowledged']} after {findings.publish['after_s']} s")
    if findings.drawn_pct is not None:
        print(f"{args.name}: the 3D panel: {findings.drawn_pct} % of it in the map's colours")
    print(
        f"{args.name}: {len(failures)} failure(s); topics listed {findings.ready_s} s after opening;"
        f" {out}/{args.name}.png, {args.name}.json"
    )
    return 1 if failures else 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name", help="names the outputs")
    parser.add_argument("--studio", required=True, help="the URL of Studio's page (serve.py)")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--ws", help="a Foxglove WebSocket URL")
    source.add_argument("--remote-file", help="an MCAP file's URL")
    source.add_argument("--local-file", help="an MCAP file's path")
    parser.add_argument("--out", required=True, help="directory for screenshots and findings")
    parser.add_argument("--layout", default="layout.json", choices=["layout.json", "layout-network.json", "layout-map.json"])
    publishing = parser.add_mutually_exclusive_group()
    publishing.add_argument("--publish", action="store_true", help="send the Publish panel's GoTo")
    publishing.add_argument("--publish-refused", action="store_true",
                            help="send it without the token: it must be refused")
    publishing.add_argument("--view-only", action="store_true",
                            help="a URL without the token: a 'publishing refused' problem is expected")
    parser.add_argument("--expect", default="", help="topics that must have messages, comma-separated")
    parser.add_argument("--absent", default="", help="topics the source lacks, comma-separated")
    parser.add_argument("--expect-delay", action="store_true", help="the Plot must show delay_ms")
    parser.add_argument("--expect-drawn", type=float, metavar="PCT",
                        help="at least PCT %% of the 3D panel in octo-delta's map's colours (Pillow)")
    parser.add_argument("--settle-s", type=float, default=15, help="seconds to watch before checking")
    parser.add_argument(
        "--within-s", type=float, default=120, help="at most this long more for data where it is blank"
    )
    args = parser.parse_args()
    if args.local_file and not Path(args.local_file).is_file():
        print(f"check.py: --local-file {args.local_file}: expected a file, found none", file=sys.stderr)
        return 2
    try:
        return run(args)
    except Setup as error:
        print(f"check.py {args.name}: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
