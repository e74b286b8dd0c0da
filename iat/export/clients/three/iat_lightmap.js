// three.js GLTFLoader plugin for the lightmaps of IAT's layered export (`iat bake --layered`).
//
//   import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
//   import iatLightmap from "./iat_lightmap.js";
//   const loader = new GLTFLoader();
//   loader.register((parser) => iatLightmap(parser));
//
// A material with `extensions.MOZ_lightmap = {index, texCoord, intensity}` (the form Mozilla Hubs
// reads) becomes a MeshBasicMaterial: colour = baseColor(TEXCOORD_0) x lightmap(TEXCOORD_<texCoord>)
// x intensity / pi, which three.js computes for a MeshBasicMaterial's lightMap; IAT writes
// intensity = pi, so the picture is albedo x illumination at the file's exposure, with no light in
// the scene. The lightmap PNG is sRGB-encoded like a base colour texture; with
// `extras.iat_illumination.encoding = "rgbm"` (`iat bake --layered --hdr`) it is RGBM: the shader
// multiplies the (sRGB-decoded) texel by its alpha x `rgbm_range`. Materials without the extension
// are left to GLTFLoader. Tested with three r187 (docs/export.md).
import { MeshBasicMaterial, SRGBColorSpace } from "three";

export const EXTENSION = "MOZ_lightmap";

export class IATLightmapPlugin {
  constructor(parser) {
    this.parser = parser;
    this.name = EXTENSION;
  }

  _lightmap(materialIndex) {
    const def = this.parser.json.materials[materialIndex];
    return def && def.extensions ? def.extensions[EXTENSION] : undefined;
  }

  getMaterialType(materialIndex) {
    return this._lightmap(materialIndex) ? MeshBasicMaterial : null;
  }

  extendMaterialParams(materialIndex, params) {
    const ext = this._lightmap(materialIndex);
    if (!ext) return Promise.resolve();
    delete params.metalness; // set by GLTFLoader for the lit material this one replaces
    delete params.roughness;
    params.lightMapIntensity = ext.intensity !== undefined ? ext.intensity : 1.0;
    const info = { index: ext.index, texCoord: ext.texCoord !== undefined ? ext.texCoord : 1 };
    return this.parser.assignTexture(params, "lightMap", info, SRGBColorSpace).then((tex) => {
      if (tex && tex.channel === 0 && info.texCoord > 0) tex.channel = info.texCoord;
    });
  }

  // RGBM lightmaps: patched on the final materials (GLTFLoader clones some, and a clone drops
  // onBeforeCompile; the extras come along as userData)
  afterRoot(gltf) {
    gltf.scene.traverse((obj) => {
      const mats = Array.isArray(obj.material) ? obj.material : obj.material ? [obj.material] : [];
      for (const mat of mats) {
        const ill = (mat.userData || {}).iat_illumination || {};
        if (ill.encoding !== "rgbm" || !mat.lightMap) continue;
        const range = Number(ill.rgbm_range || 16).toFixed(4);
        mat.onBeforeCompile = (shader) => {
          // the lightmap line of MeshBasicMaterial (and of lit materials' lights_fragment_maps)
          shader.fragmentShader = shader.fragmentShader.replace(
            "lightMapTexel.rgb * lightMapIntensity",
            "lightMapTexel.rgb * ( lightMapTexel.a * " + range + " ) * lightMapIntensity",
          );
        };
        mat.customProgramCacheKey = () => "iat-rgbm-" + range;
        mat.needsUpdate = true;
      }
    });
    return Promise.resolve();
  }
}

export default function iatLightmap(parser) {
  return new IATLightmapPlugin(parser);
}
