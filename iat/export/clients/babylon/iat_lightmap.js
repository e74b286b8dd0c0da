// Babylon.js glTF loader extension for the lightmaps of IAT's layered export (`iat bake --layered`).
//
// UMD builds (babylon.js + babylonjs.loaders / babylon.glTF2FileLoader.js, global BABYLON):
//   import registerIatLightmap from "./iat_lightmap.js";
//   registerIatLightmap(BABYLON);                   // before loading the file
// ES modules (@babylonjs/core + @babylonjs/loaders):
//   import { MaterialPluginBase } from "@babylonjs/core";
//   import { registerGLTFExtension } from "@babylonjs/loaders/glTF/2.0";
//   registerIatLightmap({ MaterialPluginBase, GLTF2: { registerGLTFExtension } });
//
// Babylon.js 9 reads no lightmap extension of its own (its loader has no MSFT_lightmap any more), so
// this extension reads IAT's `MOZ_lightmap = {index, texCoord, intensity}` (the form three.js's
// Hubs plugin reads): each material with it becomes an unlit PBRMaterial with albedoTexture = the
// base colour texture (TEXCOORD_0) and lightmapTexture = the page (TEXCOORD_<texCoord>, sRGB), used
// as a shadow map (multiplied), level = intensity / pi; so colour = albedo x illumination at the
// file's exposure, with no light in the scene. Materials without the extension are left to the
// loader. With `extras.iat_illumination.encoding = "rgbm"` (`iat bake --layered --hdr`) a material
// plugin multiplies the (sRGB-decoded) lightmap texel by its alpha x `rgbm_range` in the PBR shader's
// lightmap line. Tested with babylonjs 9.28 (docs/export.md).
export const EXTENSION = "MOZ_lightmap";

let MaterialPluginBase = null; // set by registerIatLightmap: Babylon's class, for RGBM lightmaps

// the PBR fragment shader's lightmap line (pbrBlockLightmapInit, GLSL), as a code injection regex
const LIGHTMAP_LINE = "!lightmapColor\\.rgb\\*=vLightmapInfos\\.y;";

function rgbmPlugin(material, range) {
  class IATRgbmLightmapPlugin extends MaterialPluginBase {
    constructor(mat) {
      super(mat, "IATRgbmLightmap", 200, { IAT_RGBM_LIGHTMAP: false });
      this._enable(true);
    }

    prepareDefines(defines) {
      defines.IAT_RGBM_LIGHTMAP = true;
    }

    getClassName() {
      return "IATRgbmLightmapPlugin";
    }

    getCustomCode(shaderType) {
      if (shaderType !== "fragment") return null;
      return { [LIGHTMAP_LINE]: `lightmapColor.rgb*=vLightmapInfos.y*lightmapColor.a*${range.toFixed(4)};` };
    }
  }
  return new IATRgbmLightmapPlugin(material);
}

export class IATLightmapExtension {
  constructor(loader) {
    this.name = EXTENSION;
    this.order = 200; // before the loader's own material extensions; only MOZ_lightmap materials are taken
    this._loader = loader;
    this.enabled = loader.isExtensionUsed(EXTENSION);
  }

  dispose() {
    this._loader = null;
  }

  loadMaterialPropertiesAsync(context, material, babylonMaterial) {
    const ext = material.extensions ? material.extensions[EXTENSION] : undefined;
    if (!ext) return null; // the loader's own path
    const pbr = material.pbrMetallicRoughness || {};
    const jobs = [];
    babylonMaterial.unlit = true;
    if (pbr.baseColorFactor) {
      const [r, g, b, a] = pbr.baseColorFactor;
      babylonMaterial.albedoColor.set(r, g, b);
      babylonMaterial.alpha = a;
    }
    if (pbr.baseColorTexture) {
      jobs.push(
        this._loader.loadTextureInfoAsync(`${context}/pbrMetallicRoughness/baseColorTexture`, pbr.baseColorTexture, (tex) => {
          tex.name = `${babylonMaterial.name} (Base Color)`;
          babylonMaterial.albedoTexture = tex;
        }),
      );
    }
    const info = { index: ext.index, texCoord: ext.texCoord !== undefined ? ext.texCoord : 1 };
    jobs.push(
      this._loader.loadTextureInfoAsync(`${context}/extensions/${EXTENSION}`, info, (tex) => {
        tex.name = `${babylonMaterial.name} (Lightmap)`;
        tex.level = (ext.intensity !== undefined ? ext.intensity : Math.PI) / Math.PI;
        babylonMaterial.lightmapTexture = tex;
        babylonMaterial.useLightmapAsShadowmap = true; // multiplied, not added
      }),
    );
    const ill = (material.extras || {}).iat_illumination || {};
    if (ill.encoding === "rgbm") {
      if (!MaterialPluginBase) throw new Error(`${context}: RGBM lightmap: registerIatLightmap was given no MaterialPluginBase`);
      rgbmPlugin(babylonMaterial, Number(ill.rgbm_range || 16));
    }
    if (material.doubleSided) {
      babylonMaterial.backFaceCulling = false;
      babylonMaterial.twoSidedLighting = true;
    }
    this._loader.loadMaterialAlphaProperties(context, material, babylonMaterial);
    return Promise.all(jobs).then(() => {});
  }
}

export default function registerIatLightmap(BABYLON) {
  MaterialPluginBase = BABYLON.MaterialPluginBase || null;
  BABYLON.GLTF2.registerGLTFExtension(EXTENSION, true, (loader) => new IATLightmapExtension(loader));
}
