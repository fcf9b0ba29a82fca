#!/usr/bin/env python3
"""Serves Foxglove Studio's page and files for scripts/foxglove-studio.sh, on loopback only.

Usage: serve.py PAGE_DIR MODULES_DIR DATA_DIR PORT_FILE

Serves PAGE_DIR's index.html, app.js and layouts at /, MODULES_DIR (the installed
node_modules: the bundle, React) at /node_modules/, and the regular files directly in DATA_DIR
at /data/NAME with single-range support (HTTP 206), which Studio's remote file source needs to
read an MCAP file's index and chunks. /favicon.ico is an empty answer (204), so that the page
logs no 404. The port chosen is written to PORT_FILE once the server listens.
"""

import argparse
import http.server
import mimetypes
import os
import re
import sys
import urllib.parse

RANGE = re.compile(r"bytes=(\d*)-(\d*)$")


PAGE_FILES = ("index.html", "app.js", "layout.json", "layout-network.json", "layout-map.json")


def handler_for(page_dir, modules_dir, data_dir):
    """A request handler serving the page, the modules and the data files."""

    class Handler(http.server.SimpleHTTPRequestHandler):
        extensions_map = {
            **http.server.SimpleHTTPRequestHandler.extensions_map,
            ".wasm": "application/wasm",
            ".js": "text/javascript",
            ".mcap": "application/octet-stream",
        }

        def __init__(self, *args, **kwargs):
            super().__init__(*args, directory=modules_dir, **kwargs)

        def log_message(self, format, *args):  # noqa: A002 (the base class's name)
            if os.environ.get("SERVE_LOG") == "1":
                super().log_message(format, *args)

        def do_GET(self):  # noqa: N802 (the base class's name)
            path = urllib.parse.unquote(self.path.split("?", 1)[0])
            name = path.rsplit("/", 1)[-1]
            if path == "/favicon.ico":
                self.send_response(204)
                self.end_headers()
            elif path == "/" or path.lstrip("/") in PAGE_FILES:
                self.send_file(os.path.join(page_dir, name or "index.html"))
            elif path.startswith("/node_modules/"):
                self.path = self.path[len("/node_modules") :]
                super().do_GET()
            elif path.startswith("/data/") and "/" not in path[len("/data/") :] and os.path.isfile(
                os.path.join(data_dir, name)
            ):
                self.send_file(os.path.join(data_dir, name))
            else:
                self.send_error(404, f"{path}: not served")

        def send_file(self, file_path):
            size = os.path.getsize(file_path)
            start, end = 0, size - 1
            wanted = self.headers.get("Range")
            status = 200
            if wanted:
                match = RANGE.match(wanted.strip())
                if not match or (not match.group(1) and not match.group(2)):
                    self.send_error(416, f"unsupported range {wanted!r}")
                    return
                if match.group(1):
                    start = int(match.group(1))
                    end = int(match.group(2)) if match.group(2) else size - 1
                else:
                    start = max(0, size - int(match.group(2)))
                end = min(end, size - 1)
                if start > end:
                    self.send_response(416)
                    self.send_header("Content-Range", f"bytes */{size}")
                    self.end_headers()
                    return
                status = 206
            self.send_response(status)
            self.send_header("Content-Type", mimetypes.guess_type(file_path)[0] or "application/octet-stream")
            self.send_header("Accept-Ranges", "bytes")
            self.send_header("Content-Length", str(end - start + 1))
            if status == 206:
                self.send_header("Content-Range", f"bytes {start}-{end}/{size}")
            self.end_headers()
            with open(file_path, "rb") as file:
                file.seek(start)
                left = end - start + 1
                while left > 0:
                    block = file.read(min(left, 1 << 20))
                    if not block:
                        break
                    self.wfile.write(block)
                    left -= len(block)

    return Handler


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("page_dir")
    parser.add_argument("modules_dir")
    parser.add_argument("data_dir")
    parser.add_argument("port_file")
    args = parser.parse_args()
    for what, directory in [("PAGE_DIR", args.page_dir), ("MODULES_DIR", args.modules_dir), ("DATA_DIR", args.data_dir)]:
        if not os.path.isdir(directory):
            print(f"serve.py: {what} {directory}: expected a directory, found none", file=sys.stderr)
            return 2
    handler = handler_for(args.page_dir, args.modules_dir, args.data_dir)
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    with open(args.port_file + ".tmp", "w") as file:
        file.write(f"{server.server_address[1]}\n")
    os.replace(args.port_file + ".tmp", args.port_file)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
