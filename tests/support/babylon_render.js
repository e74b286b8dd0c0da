// Draw GLB files with Babylon.js in headless Chromium: node tests/support/babylon_render.js JOBS.json
//
// JOBS.json: {"babylon": DIR (npm `babylonjs`), "loaders": DIR (npm `babylonjs-loaders`), "chromium":
//   PATH, "jobs": [{"glb": PATH, "out": PATH.png, "width": W, "height": H, "camera": K,
//   "clear": "#ff00ff", "plugin": PATH.js or null}, ...]}
// Each job: a Babylon.js engine (no antialiasing, preserveDrawingBuffer, no tone mapping: the
// scene's default image processing, which writes sRGB) loads the file with the glTF 2 loader
// (the plugin's default export called with BABYLON first, if given: IAT's MOZ_lightmap extension);
// the Babylon camera made from the file's K-th glTF camera draws it (aspect W / H); the canvas is
// written as an 8-bit PNG. Prints one JSON line as three_render.js does ("materials": Babylon
// material classes, "+unlit", "+lightmap", "+rgbm"); exit 0, or 2 with the error on stderr. The browser side
// is browser_jobs.js.
"use strict";
const { main } = require("./browser_jobs.js");

const PAGE = `<!doctype html><html><body style="margin:0">
<script src="/babylon/babylon.js"></script>
<script src="/loaders/babylon.glTF2FileLoader.js"></script>
<script type="module">
window.renderJob = async (job) => {
  const canvas = document.createElement("canvas");
  canvas.width = job.width; canvas.height = job.height;
  document.body.appendChild(canvas);
  const engine = new BABYLON.Engine(canvas, false, { preserveDrawingBuffer: true, stencil: false, useExactSrgbConversions: true }, false);
  engine.setHardwareScalingLevel(1);
  const scene = new BABYLON.Scene(engine);
  scene.clearColor = BABYLON.Color4.FromHexString(job.clear + "ff");
  scene.imageProcessingConfiguration.toneMappingEnabled = false;
  if (job.plugin) {
    const mod = await import(job.plugin);
    mod.default(BABYLON);
  }
  let json = null;
  const seen = BABYLON.SceneLoader.OnPluginActivatedObservable.add((plugin) => {
    if (plugin.name === "gltf") plugin.onParsedObservable.addOnce((data) => { json = data.json; });
  });
  await BABYLON.AppendSceneAsync(job.glb, scene, { pluginExtension: ".glb" });
  BABYLON.SceneLoader.OnPluginActivatedObservable.remove(seen);
  const cams = (json && json.cameras) || [];
  if (job.camera >= cams.length) throw new Error("the file has " + cams.length + " camera(s), not " + (job.camera + 1));
  const name = cams[job.camera].name;
  const found = scene.cameras.filter((c) => c.name === name);
  if (found.length !== 1) throw new Error(found.length + " Babylon cameras named " + name);
  scene.activeCamera = found[0];
  await scene.whenReadyAsync();
  scene.render();
  const types = new Set();
  for (const m of scene.meshes) {
    if (m.material && m.getTotalVertices() > 0) {
      const mat = m.material, rgbm = mat.pluginManager && mat.pluginManager.getPlugin("IATRgbmLightmap");
      types.add(mat.getClassName() + (mat.unlit ? "+unlit" : "") + (mat.lightmapTexture ? "+lightmap" : "") + (rgbm ? "+rgbm" : ""));
    }
  }
  const out = window.canvasResult(canvas, canvas.getContext("webgl2") || canvas.getContext("webgl"), types);
  engine.dispose();
  canvas.remove();
  return out;
};
window.ready = true;
</script></body></html>`;

main(PAGE, (spec) => ({ babylon: spec.babylon, loaders: spec.loaders }));
