// Renders Foxglove Studio's App from the @foxglove/studio-base bundle (window.StudioBase) the
// way the web app does: fonts and translations first, then <App> with the data sources a
// browser offers. Layouts and settings live in memory: the one layout is layout.json (or the
// one ?layout= names), served beside this file, and it is the current one (studio.profile-data
// in localStorage, set here).
"use strict";

(async () => {
  const base = window.StudioBase;
  const h = window.React.createElement;

  /** ILayoutStorage in memory, namespaced as Studio's LayoutManager asks. */
  class MemoryLayoutStorage {
    constructor() {
      this.layouts = new Map();
    }
    key(namespace, id) {
      return `${namespace}\u0000${id}`;
    }
    async list(namespace) {
      return [...this.layouts.entries()]
        .filter(([key]) => key.startsWith(`${namespace}\u0000`))
        .map(([, layout]) => layout);
    }
    async get(namespace, id) {
      return this.layouts.get(this.key(namespace, id));
    }
    async put(namespace, layout) {
      this.layouts.set(this.key(namespace, layout.id), layout);
      return layout;
    }
    async delete(namespace, id) {
      this.layouts.delete(this.key(namespace, id));
    }
    async importLayouts() {}
    async migrateUnnamespacedLayouts() {}
  }

  /** IAppConfiguration in memory. */
  class MemoryConfiguration {
    constructor(values) {
      this.values = new Map(Object.entries(values));
      this.listeners = new Map();
    }
    get(key) {
      return this.values.get(key);
    }
    async set(key, value) {
      this.values.set(key, value);
      for (const cb of this.listeners.get(key) ?? []) {
        cb(value);
      }
    }
    addChangeListener(key, cb) {
      this.listeners.set(key, [...(this.listeners.get(key) ?? []), cb]);
    }
    removeChangeListener(key, cb) {
      this.listeners.set(key, (this.listeners.get(key) ?? []).filter((other) => other !== cb));
    }
  }

  // ?layout=NAME picks another layout file served beside this one (layout-network.json).
  const layoutName = new URLSearchParams(window.location.search).get("layout") ?? "layout.json";
  if (!/^layout[-a-z]*\.json$/.test(layoutName)) {
    throw new Error(`?layout=${layoutName}: expected layout.json or layout-NAME.json`);
  }
  const layoutData = await (await fetch(layoutName)).json();
  const layoutStorage = new MemoryLayoutStorage();
  const layoutId = "rovlink-check";
  await layoutStorage.put("local", {
    id: layoutId,
    name: "rovlink check",
    permission: "CREATOR_WRITE",
    baseline: { data: layoutData, savedAt: new Date().toISOString() },
    working: undefined,
    syncInfo: undefined,
  });
  // The profile: that layout, and the 3D panel's first-run tooltip already shown.
  localStorage.setItem(
    "studio.profile-data",
    JSON.stringify({
      currentLayoutId: layoutId,
      onboarding: { settingsTooltipShownForPanelTypes: ["3D"] },
    }),
  );

  base.overwriteFetch();
  await base.waitForFonts();
  await base.initI18n();

  const dataSources = [
    new base.FoxgloveWebSocketDataSourceFactory(),
    new base.McapLocalDataSourceFactory(),
    new base.RemoteDataSourceFactory(),
  ];
  window.ReactDOM.render(
    h(base.App, {
      deepLinks: [window.location.href],
      dataSources,
      appConfiguration: new MemoryConfiguration({}),
      layoutStorage,
      extensionLoaders: [],
      enableGlobalCss: true,
    }),
    document.getElementById("root"),
  );
  console.debug("App rendered");
})().catch((error) => {
  console.error(`rovlink check: Studio did not start: ${error.stack ?? error}`);
});
