// Draw GLB files with three.js in headless Chromium: node tests/support/three_render.js JOBS.json
//
// JOBS.json: {"three": DIR (the npm package `three`), "chromium": PATH, "jobs": [{"glb": PATH,
//   "out": PATH.png, "width": W, "height": H, "camera": K, "clear": "#ff00ff",
//   "plugin": PATH.js or null}, ...]}
// Each job: GLTFLoader (with the plugin's default export registered, if given) loads the file; the
// file's K-th camera draws it (aspect W / H) into a canvas with outputColorSpace = SRGB, no tone
// mapping, no antialiasing, preserveDrawingBuffer; the canvas is written as an 8-bit PNG.
// Prints one JSON line: [{"out": ..., "warnings": [console warnings and errors], "materials":
//   [three.js material types], "attempts": n, "blank": whether the canvas stayed blank}, ...]
// (a blank canvas is drawn again, at most three times); exit 0, or 2 with the error on stderr.
// Needs puppeteer-core on the module path (NODE_PATH, see the Makefile); Chromium runs with
// SwiftShader (--use-gl=swiftshader --enable-unsafe-swiftshader), no GPU needed.
"use strict";
const fs = require("fs");
const http = require("http");
const path = require("path");
const puppeteer = require("puppeteer-core");

const spec = JSON.parse(fs.readFileSync(process.argv[2], "utf8"));
const TYPES = { ".js": "text/javascript", ".html": "text/html", ".glb": "model/gltf-binary" };

const PAGE = `<!doctype html><html><body style="margin:0">
<script type="importmap">{"imports": {"three": "/three/build/three.module.js",
  "three/addons/": "/three/examples/jsm/"}}</script>
<script type="module">
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
window.renderJob = async (job) => {
  const canvas = document.createElement("canvas");
  canvas.width = job.width; canvas.height = job.height;
  document.body.appendChild(canvas);
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(job.width, job.height, false);
  renderer.outputColorSpace = THREE.SRGBColorSpace;
  renderer.toneMapping = THREE.NoToneMapping;
  renderer.setClearColor(new THREE.Color(job.clear), 1.0);
  const loader = new GLTFLoader();
  if (job.plugin) {
    const mod = await import(job.plugin);
    loader.register((parser) => mod.default(parser));
  }
  const gltf = await loader.loadAsync(job.glb);
  const camera = gltf.cameras[job.camera];
  if (!camera) throw new Error("the file has " + gltf.cameras.length + " camera(s), not " + (job.camera + 1));
  camera.aspect = job.width / job.height;
  camera.updateProjectionMatrix();
  gltf.scene.updateMatrixWorld(true);
  renderer.render(gltf.scene, camera);
  const types = new Set();
  gltf.scene.traverse((o) => { if (o.material) types.add(o.material.type + (o.material.lightMap ? "+lightMap" : "")); });
  const gl = renderer.getContext();
  const px = new Uint8Array(job.width * job.height * 4);
  gl.readPixels(0, 0, job.width, job.height, gl.RGBA, gl.UNSIGNED_BYTE, px);
  let opaque = 0;
  for (let i = 3; i < px.length; i += 4) opaque += px[i] === 255 ? 1 : 0;
  const lost = gl.isContextLost();
  const url = canvas.toDataURL("image/png");
  renderer.dispose();
  canvas.remove();
  return { png: url, materials: [...types].sort(), blank: lost || opaque === 0 };
};
window.ready = true;
</script></body></html>`;

function serve(files) {
  return http.createServer((req, res) => {
    const url = decodeURIComponent(req.url.split("?")[0]);
    let file = null;
    if (url === "/favicon.ico") { res.writeHead(204); return res.end(); }
    if (url === "/" || url === "/index.html") {
      res.writeHead(200, { "Content-Type": "text/html" });
      return res.end(PAGE);
    }
    if (url.startsWith("/three/")) file = path.join(spec.three, url.slice(7));
    else if (url.startsWith("/f/")) file = files[Number(url.slice(3).split(".")[0])];
    if (!file || !fs.existsSync(file) || (url.startsWith("/three/") && !path.resolve(file).startsWith(path.resolve(spec.three)))) {
      res.writeHead(404);
      return res.end();
    }
    res.writeHead(200, { "Content-Type": TYPES[path.extname(file)] || "application/octet-stream" });
    fs.createReadStream(file).pipe(res);
  });
}

async function main() {
  const files = [];
  const add = (p) => { files.push(path.resolve(p)); return "/f/" + (files.length - 1) + path.extname(p); };
  const jobs = spec.jobs.map((j) => ({ ...j, glb: add(j.glb), plugin: j.plugin ? add(j.plugin) : null,
    clear: j.clear || "#ff00ff", camera: j.camera || 0 }));
  const server = serve(files);
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
      // a blank canvas (SwiftShader's context lost on a loaded machine) is drawn again, twice at most
      for (let attempt = 0; attempt < 3; attempt++) {
        const page = await browser.newPage();
        const warnings = [];
        page.on("console", (m) => { if (m.type() === "warn" || m.type() === "error") warnings.push(m.text()); });
        page.on("pageerror", (e) => warnings.push(String(e)));
        await page.goto(base + "/index.html");
        await page.waitForFunction("window.ready === true", { timeout: 60000 });
        const r = await page.evaluate((j) => window.renderJob(j), job);
        await page.close();
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

main().catch((e) => { console.error(String(e && e.stack ? e.stack : e)); process.exit(2); });
