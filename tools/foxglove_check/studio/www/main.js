// Minimal host for @foxglove/studio-base 1.48's prebuilt App, as Foxglove's own web app
// (packages/studio-web) hosts it: in-memory app settings, and a layout storage that holds one
// layout, fetched from the `layout` URL parameter and selected as the current layout. The data
// source comes from the usual deep link (`ds=remote-file&ds.url=...`).
//
// `compat=1` rewrites the layout's Image panels for Studio 1.48, whose "Image" panel (then
// experimental) ignores annotations and colour maps: colour and mask become 1.48's default
// image panel ("ImageViewPanel", annotations via enabledMarkerTopics, 16-bit range via
// minValue/maxValue). Everything else (3D panel, plot, topics, frames) is the layout unchanged.
"use strict";

function toStudio148(layout) {
  const out = JSON.parse(JSON.stringify(layout));
  const renamed = new Map();
  for (const [id, config] of Object.entries(layout.configById)) {
    if (!id.startsWith("Image!") || !config.imageMode) continue;
    const mode = config.imageMode;
    const newId = id.replace(/^Image!/, "ImageViewPanel!");
    renamed.set(id, newId);
    delete out.configById[id];
    out.configById[newId] = {
      cameraTopic: mode.imageTopic,
      enabledMarkerTopics: Object.entries(mode.annotations ?? {})
        .filter(([, s]) => s?.visible !== false)
        .map(([t]) => t),
      synchronize: mode.synchronize ?? false,
      ...(mode.minValue != undefined ? { minValue: mode.minValue } : {}),
      ...(mode.maxValue != undefined ? { maxValue: mode.maxValue } : {}),
      mode: "fit",
      transformMarkers: false,
    };
  }
  const rename = (node) =>
    typeof node === "string"
      ? renamed.get(node) ?? node
      : { ...node, first: rename(node.first), second: rename(node.second) };
  out.layout = rename(layout.layout);
  return out;
}

(async function main() {
  const params = new URL(window.location.href).searchParams;
  const h = React.createElement;
  const settings = new Map([
    ["telemetry.telemetryEnabled", false],
    ["telemetry.crashReportingEnabled", false],
    ["colorScheme", params.get("theme") ?? "light"],
  ]);
  const appConfiguration = {
    get: (key) => settings.get(key),
    set: async (key, value) => void settings.set(key, value),
    addChangeListener: () => {},
    removeChangeListener: () => {},
  };
  let layoutData = await (await fetch(params.get("layout"))).json();
  if (params.get("compat") === "1") layoutData = toStudio148(layoutData);
  // `panel=ID`: that panel of the layout alone fills the window; `camera={...}` moves the 3D
  // panels' view (cameraState fields, as a user orbits), the rest of their configuration unchanged.
  if (params.get("panel")) layoutData = { ...layoutData, layout: params.get("panel") };
  if (params.get("camera")) {
    for (const [id, config] of Object.entries(layoutData.configById)) {
      if (!id.startsWith("3D!")) continue;
      config.cameraState = { ...config.cameraState, ...JSON.parse(params.get("camera")) };
    }
  }
  window.occmaskLayout = layoutData;
  const now = new Date().toISOString();
  const layouts = new Map([
    [
      "occmask",
      {
        id: "occmask",
        name: "occmask",
        permission: "CREATOR_WRITE",
        baseline: { data: layoutData, savedAt: now },
        working: undefined,
        syncInfo: undefined,
      },
    ],
  ]);
  const layoutStorage = {
    list: async () => [...layouts.values()],
    get: async (_namespace, id) => layouts.get(id),
    put: async (_namespace, layout) => (layouts.set(layout.id, layout), layout),
    delete: async (_namespace, id) => void layouts.delete(id),
    importLayouts: async () => {},
  };
  // Select the layout, and mark the panels' first-use settings hints as seen (they would cover
  // the panels in screenshots).
  localStorage.setItem(
    "studio.profile-data",
    JSON.stringify({
      currentLayoutId: "occmask",
      onboarding: { settingsTooltipShownForPanelTypes: ["3D", "Image", "ImageViewPanel", "Plot"] },
    }),
  );
  await initI18n();
  ReactDOM.render(
    h(App, {
      deepLinks: [window.location.href],
      appConfiguration,
      dataSources: [new RemoteDataSourceFactory(), new McapLocalDataSourceFactory()],
      layoutStorage,
      extensionLoaders: [],
      enableGlobalCss: true,
      enableLaunchPreferenceScreen: false,
    }),
    document.getElementById("root"),
  );
})().catch((e) => {
  console.error("host failed", e);
  document.body.textContent = `host failed: ${e}`;
});
