// Babylon.js glTF loader extension for the lightmaps of IAT's layered export (`iat bake --layered`).
//
// UMD builds (babylon.js + babylonjs.loaders / babylon.glTF2FileLoader.js, global BABYLON):
//   import registerIatLightmap from "./iat_lightmap.js";
//   registerIatLightmap(BABYLON);                   // before loading the file
// ES modules (@babylonjs/core + @babylonjs/loaders):
//   import { registerGLTFExtension } from "@babylonjs/loaders/glTF/2.0";
//   import { EXTENSION, IATLightmapExtension } from "./iat_lightmap.js";
//   registerGLTFExtension(EXTENSION, true, (loader) => new IATLightmapExtension(loader));
//
// Babylon.js 9 reads no lightmap extension of its own (its loader has no MSFT_lightmap any more), so
// this extension reads IAT's `MOZ_lightmap = {index, texCoord, intensity}` (the form three.js's
// Hubs plugin reads): each material with it becomes an unlit PBRMaterial with albedoTexture = the
// base colour texture (TEXCOORD_0) and lightmapTexture = the page (TEXCOORD_<texCoord>, sRGB), used
// as a shadow map (multiplied), level = intensity / pi; so colour = albedo x illumination at the
// file's exposure, with no light in the scene. Materials without the extension are left to the
// loader. RGBM lightmaps (`iat bake --layered --hdr`) are not decoded here (three.js plugin and
// Blender script only). Tested with babylonjs 9.28 (docs/export.md).
export const EXTENSION = "MOZ_lightmap";

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
    if (material.doubleSided) {
      babylonMaterial.backFaceCulling = false;
      babylonMaterial.twoSidedLighting = true;
    }
    this._loader.loadMaterialAlphaProperties(context, material, babylonMaterial);
    return Promise.all(jobs).then(() => {});
  }
}

export default function registerIatLightmap(BABYLON) {
  BABYLON.GLTF2.registerGLTFExtension(EXTENSION, true, (loader) => new IATLightmapExtension(loader));
}
