// Static file server with HTTP Range support (Foxglove's remote-file MCAP reader reads by range).
// Usage: node server.js PORT URL_PREFIX=DIR [URL_PREFIX=DIR ...]
"use strict";
const http = require("http");
const fs = require("fs");
const path = require("path");

const port = Number(process.argv[2]);
const mounts = process.argv.slice(3).map((m) => {
  const [prefix, dir] = m.split("=");
  return { prefix, dir: path.resolve(dir) };
});
const TYPES = {
  ".html": "text/html",
  ".js": "text/javascript",
  ".json": "application/json",
  ".wasm": "application/wasm",
  ".png": "image/png",
  ".woff2": "font/woff2",
  ".ttf": "font/ttf",
};

function resolve(urlPath) {
  for (const { prefix, dir } of mounts) {
    if (urlPath.startsWith(prefix)) {
      const file = path.join(dir, urlPath.slice(prefix.length));
      return file.startsWith(dir) ? file : undefined;
    }
  }
  return undefined;
}

http
  .createServer((req, res) => {
    const file = resolve(decodeURIComponent(new URL(req.url, "http://localhost").pathname));
    if (!file) {
      res.writeHead(404).end();
      return;
    }
    fs.stat(file, (err, st) => {
      if (err || !st.isFile()) {
        res.writeHead(404).end();
        return;
      }
      const headers = {
        "Content-Type": TYPES[path.extname(file)] ?? "application/octet-stream",
        "Accept-Ranges": "bytes",
      };
      const range = /bytes=(\d+)-(\d*)/.exec(req.headers.range ?? "");
      if (range) {
        const start = Number(range[1]);
        const end = range[2] ? Math.min(Number(range[2]), st.size - 1) : st.size - 1;
        res.writeHead(206, {
          ...headers,
          "Content-Range": `bytes ${start}-${end}/${st.size}`,
          "Content-Length": end - start + 1,
        });
        fs.createReadStream(file, { start, end }).pipe(res);
      } else {
        res.writeHead(200, { ...headers, "Content-Length": st.size });
        if (req.method === "HEAD") res.end();
        else fs.createReadStream(file).pipe(res);
      }
    });
  })
  .listen(port, "127.0.0.1", () => process.stdout.write(`listening on http://127.0.0.1:${port}\n`));
