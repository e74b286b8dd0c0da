// The browser side shared by three_render.js and babylon_render.js: a local HTTP server (the page,
// the client library's folders, the job files) and headless Chromium through puppeteer-core.
//
// runJobs(spec, page, roots): serves `page` at /index.html and each roots[prefix] folder at /prefix/,
// opens the page once per job (with window.canvasResult(canvas, gl, materials) defined for its
// renderJob to return), calls window.renderJob(job) (job.glb and job.plugin rewritten to
// served URLs) and writes the returned PNG data URL to spec.jobs[i].out. Prints one JSON line:
// [{"out", "warnings": [console warnings and errors], "materials", "attempts", "blank"}, ...]; a
// blank canvas (SwiftShader's context lost on a loaded machine) is drawn again, twice at most.
// Chromium runs with SwiftShader (--use-gl=swiftshader --enable-unsafe-swiftshader), no GPU needed.
"use strict";
const fs = require("fs");
const http = require("http");
const path = require("path");
const puppeteer = require("puppeteer-core");

const TYPES = { ".js": "text/javascript", ".html": "text/html", ".glb": "model/gltf-binary" };

// defined in every page before its own scripts: what renderJob returns, from the drawn canvas and
// its WebGL context (read before the client library disposes of it); blank: no opaque pixel or the
// context lost
const CANVAS_RESULT = `window.canvasResult = (canvas, gl, types) => {
  const px = new Uint8Array(canvas.width * canvas.height * 4);
  gl.readPixels(0, 0, canvas.width, canvas.height, gl.RGBA, gl.UNSIGNED_BYTE, px);
  let opaque = 0;
  for (let i = 3; i < px.length; i += 4) opaque += px[i] === 255 ? 1 : 0;
  const blank = gl.isContextLost() || opaque === 0;
  return { png: canvas.toDataURL("image/png"), materials: [...types].sort(), blank };
};`;

function serve(page, roots, files) {
  return http.createServer((req, res) => {
    const url = decodeURIComponent(req.url.split("?")[0]);
    if (url === "/favicon.ico") { res.writeHead(204); return res.end(); }
    if (url === "/" || url === "/index.html") {
      res.writeHead(200, { "Content-Type": "text/html" });
      return res.end(page);
    }
    let file = null;
    for (const [prefix, dir] of Object.entries(roots)) {
      if (url.startsWith("/" + prefix + "/")) {
        const p = path.resolve(dir, url.slice(prefix.length + 2));
        if (p.startsWith(path.resolve(dir) + path.sep)) file = p;
      }
    }
    if (url.startsWith("/f/")) file = files[Number(url.slice(3).split(".")[0])];
    if (!file || !fs.existsSync(file)) {
      res.writeHead(404);
      return res.end();
    }
    res.writeHead(200, { "Content-Type": TYPES[path.extname(file)] || "application/octet-stream" });
    fs.createReadStream(file).pipe(res);
  });
}

async function runJobs(spec, page, roots) {
  const files = [];
  const add = (p) => { files.push(path.resolve(p)); return "/f/" + (files.length - 1) + path.extname(p); };
  const jobs = spec.jobs.map((j) => ({ ...j, glb: add(j.glb), plugin: j.plugin ? add(j.plugin) : null,
    clear: j.clear || "#ff00ff", camera: j.camera || 0 }));
  const server = serve(page, roots, files);
  await new Promise((ok) => server.listen(0, "127.0.0.1", ok));
  const base = "http://127.0.0.1:" + server.address().port;
  const browser = await puppeteer.launch({
    executablePath: spec.chromium || "/usr/bin/chromium",
    headless: true,
    args: ["--no-sandbox", "--use-gl=swiftshader", "--enable-unsafe-swiftshader", "--disable-gpu-sandbox"],
  });
  const out = [];
  try {
    for (const [i, job] of jobs.entries()) {
      for (let attempt = 0; attempt < 3; attempt++) {
        const tab = await browser.newPage();
        await tab.evaluateOnNewDocument(CANVAS_RESULT);
        const warnings = [];
        tab.on("console", (m) => { if (m.type() === "warn" || m.type() === "error") warnings.push(m.text()); });
        tab.on("pageerror", (e) => warnings.push(String(e)));
        await tab.goto(base + "/index.html");
        await tab.waitForFunction("window.ready === true", { timeout: 60000 });
        const r = await tab.evaluate((j) => window.renderJob(j), job);
        await tab.close();
        if (r.blank && attempt < 2) continue;
        fs.writeFileSync(spec.jobs[i].out, Buffer.from(r.png.split(",")[1], "base64"));
        out.push({ out: spec.jobs[i].out, warnings, materials: r.materials, attempts: attempt + 1, blank: r.blank });
        break;
      }
    }
  } finally {
    await browser.close();
    server.close();
  }
  console.log(JSON.stringify(out));
}

function main(page, roots) {
  const spec = JSON.parse(fs.readFileSync(process.argv[2], "utf8"));
  runJobs(spec, page, roots(spec)).catch((e) => {
    console.error(String(e && e.stack ? e.stack : e));
    process.exit(2);
  });
}

module.exports = { runJobs, main };
