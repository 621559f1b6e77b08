#!/usr/bin/env node
// Opens an MCAP file in Foxglove Studio 1.48 (the @foxglove/studio-base web bundle from npm,
// hosted by www/) in headless Chromium with a layout, seeks to the given times and saves a
// screenshot of the whole window at each. Usage:
//
//   node screenshots.js --mcap FILE --layout LAYOUT.json --out PREFIX [--times 1,2.5] [--compat]
//       [--width 1280] [--height 800] [--wait-ms 15000] [--chromium /usr/bin/chromium]
//       [--panel ID] [--camera JSON]
//
// Writes PREFIX-<seconds>s.png (seconds after the file's first message). --compat rewrites the
// Image panels for Studio 1.48 (see www/main.js); --panel shows only the layout's panel ID (e.g.
// 3D!occmask-scene), with its configuration unchanged; --camera '{"distance":5}' moves the 3D
// panels' view (fields of their cameraState). Needs `npm ci` here and in .. (for @mcap/core).
"use strict";

const fs = require("fs");
const path = require("path");
const { spawn } = require("child_process");
const { chromium } = require("playwright-core");
const { McapIndexedReader } = require("../node_modules/@mcap/core");

const PORT = 18765;

function option(args, name, fallback) {
  const i = args.indexOf(`--${name}`);
  return i >= 0 ? args[i + 1] : fallback;
}

async function firstMessageNs(file) {
  const fd = fs.openSync(file, "r");
  const size = fs.fstatSync(fd).size;
  const reader = await McapIndexedReader.Initialize({
    readable: {
      size: async () => BigInt(size),
      read: async (offset, length) => {
        const buf = Buffer.alloc(Number(length));
        fs.readSync(fd, buf, 0, buf.length, Number(offset));
        return buf;
      },
    },
  });
  fs.closeSync(fd);
  return reader.statistics.messageStartTime;
}

function rfc3339(ns) {
  const sec = ns / 1000000000n;
  const nsec = (ns % 1000000000n).toString().padStart(9, "0");
  return `${new Date(Number(sec) * 1000).toISOString().slice(0, 19)}.${nsec}Z`;
}

async function main() {
  const args = process.argv.slice(2);
  const mcap = path.resolve(option(args, "mcap"));
  const layout = path.resolve(option(args, "layout"));
  const out = path.resolve(option(args, "out"));
  const times = option(args, "times", "1").split(",").map(Number);
  const width = Number(option(args, "width", "1280"));
  const height = Number(option(args, "height", "800"));
  const waitMs = Number(option(args, "wait-ms", "15000"));
  const compat = args.includes("--compat");
  const panel = option(args, "panel", undefined);
  const camera = option(args, "camera", undefined);
  const executablePath = option(args, "chromium", "/usr/bin/chromium");

  const start = await firstMessageNs(mcap);
  const server = spawn(
    process.execPath,
    [
      path.join(__dirname, "server.js"),
      String(PORT),
      `/modules/=${path.join(__dirname, "node_modules")}`,
      `/data/=${path.dirname(mcap)}`,
      `/layout/=${path.dirname(layout)}`,
      `/=${path.join(__dirname, "www")}`,
    ],
    { stdio: ["ignore", "pipe", "inherit"] },
  );
  await new Promise((ok) => server.stdout.once("data", ok));
  const browser = await chromium.launch({
    executablePath,
    // SwiftShader gives the 3D panel WebGL without a GPU.
    args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
  });
  try {
    const page = await browser.newPage({ viewport: { width, height } });
    page.on("pageerror", (e) => process.stderr.write(`page error: ${e.message}\n`));
    page.on("console", (m) => {
      if (m.type() === "error" && !m.text().includes("404")) process.stderr.write(`console: ${m.text().slice(0, 300)}\n`);
    });
    for (const t of times) {
      const at = start + BigInt(Math.round(t * 1e9));
      const url = new URL(`http://127.0.0.1:${PORT}/index.html`);
      url.searchParams.set("layout", `/layout/${path.basename(layout)}`);
      if (compat) url.searchParams.set("compat", "1");
      if (panel) url.searchParams.set("panel", panel);
      if (camera) url.searchParams.set("camera", camera);
      url.searchParams.set("ds", "remote-file");
      url.searchParams.set("ds.url", `http://127.0.0.1:${PORT}/data/${path.basename(mcap)}`);
      url.searchParams.set("time", rfc3339(at));
      await page.goto(url.href);
      await page.waitForTimeout(waitMs);
      // Close the left sidebar (data source info) so the panels get the window.
      const sidebarButton = page.locator('[data-testid="DataSourceInfo"], [data-sidebar-key="connection"]').first();
      if (await sidebarButton.count()) await sidebarButton.click().catch(() => {});
      await page.waitForTimeout(1500);
      const file = `${out}-${t}s.png`;
      await page.screenshot({ path: file });
      process.stdout.write(`${file}\n`);
    }
  } finally {
    await browser.close();
    server.kill();
  }
}

main().catch((e) => {
  process.stderr.write(`error: ${e.stack ?? e}\n`);
  process.exit(1);
});
