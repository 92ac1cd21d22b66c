// The page at http://HOST:PORT/ in Debian's Chromium (headless, software WebGL): the world, the
// followed car with its arrows and the plots, over the same WebSocket; two screenshots a moment
// apart show the car and the plots move. The screenshots stay in the test's folder to look at.
"use strict";
const { test, after } = require("node:test");
const assert = require("node:assert/strict");
const path = require("path");
const { chromium } = require("playwright-core");
const h = require("./harness");

let browser;
after(async () => {
  if (browser) await browser.close();
  await h.stopGracefully();
});

// Pixels of two PNG screenshots of the same size that differ, in a rectangle (page pixels).
async function changed(page, a, b, rect) {
  return page.evaluate(async ({ a, b, rect }) => {
    const load = (src) => new Promise((resolve) => { const i = new Image(); i.onload = () => resolve(i); i.src = src; });
    const [ia, ib] = await Promise.all([load(a), load(b)]);
    const c = document.createElement("canvas");
    c.width = ia.width; c.height = ia.height;
    const g = c.getContext("2d");
    const px = (img) => { g.drawImage(img, 0, 0); return g.getImageData(rect.x, rect.y, rect.width, rect.height).data; };
    const pa = px(ia), pb = px(ib);
    let n = 0;
    for (let i = 0; i < pa.length; i += 4) if (Math.abs(pa[i] - pb[i]) + Math.abs(pa[i + 1] - pb[i + 1]) + Math.abs(pa[i + 2] - pb[i + 2]) > 30) n++;
    return n;
  }, { a: "data:image/png;base64," + a.toString("base64"), b: "data:image/png;base64," + b.toString("base64"), rect });
}

test("the page shows the world, the car and its plots, and they move", async () => {
  h.server(["--vehicle-ids", "1,2"]);
  h.demoDrive(["--loop"]);  // still driving however long the browser takes to start
  const b = await h.bridge("bridge");
  browser = await chromium.launch({
    executablePath: "/usr/bin/chromium",
    args: ["--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
           "--disable-quic", "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync"],
  });
  const page = await browser.newPage({ viewport: { width: 1200, height: 700 } });
  const errors = [];
  page.on("pageerror", (e) => errors.push(e.message));
  page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
  await page.goto(`http://127.0.0.1:${b.port}/?follow=1`);
  // Everything arrived: the terrain, both cars' scenes and transforms, the followed car's states.
  await page.waitForFunction(() => window.vdyn.worldTriangles > 1000 && window.vdyn.scenes > 60 &&
                             window.vdyn.states > 500 && window.vdyn.pose && window.vdyn.speedKmh > 15,
                             null, { timeout: 40000 });
  const plotRect = await page.evaluate(() => { const r = document.getElementById("plots").getBoundingClientRect(); return { x: Math.round(r.x), y: Math.round(r.y), width: Math.round(r.width), height: Math.round(r.height) }; });
  const viewRect = await page.evaluate(() => { const r = document.getElementById("view").getBoundingClientRect(); return { x: Math.round(r.x), y: Math.round(r.y), width: Math.round(r.width), height: Math.round(r.height) }; });
  const first = await page.evaluate(() => ({ ...window.vdyn.pose, states: window.vdyn.states, plotted: window.vdyn.plotted }));
  const a = await page.screenshot({ path: path.join(h.work, "page-1.png") });
  // 1.5 s of the drive or more, until the car has moved 3 m (the bridge skips a stale backlog, so
  // on a loaded machine the page may jump to where the car is now).
  await page.waitForFunction((f) => window.vdyn.states > f.states + 1500 &&
                             Math.hypot(window.vdyn.pose.x - f.x, window.vdyn.pose.y - f.y) > 3,
                             first, { timeout: 60000 }).catch(() => {});
  const b2 = await page.screenshot({ path: path.join(h.work, "page-2.png") });
  const second = await page.evaluate(() => ({ ...window.vdyn.pose, plotted: window.vdyn.plotted }));
  assert.deepEqual(errors, []);
  // The followed car moved (the camera with it), and the plots took new points.
  assert.ok(Math.hypot(second.x - first.x, second.y - first.y) > 3, `the car moved from ${JSON.stringify(first)} to ${JSON.stringify(second)}`);
  assert.ok(second.plotted > first.plotted + 100);
  // Both moments on screen differ: the 3D view and the plots were drawn anew.
  const inView = await changed(page, a, b2, viewRect);
  const inPlots = await changed(page, a, b2, plotRect);
  assert.ok(inView > 0.02 * viewRect.width * viewRect.height, `${inView} pixels changed in the 3D view`);
  assert.ok(inPlots > 500, `${inPlots} pixels changed in the plots`);
  // The car is drawn: the followed vehicle's body colour (the viewer's palette, vehicle 1:
  // 90, 170, 200, lit) is on screen near the middle of the view.
  const body = await page.evaluate(() => {
    const c = document.querySelector("#view canvas");
    const g = document.createElement("canvas");
    g.width = c.width; g.height = c.height;
    const x = g.getContext("2d");
    x.drawImage(c, 0, 0);
    const d = x.getImageData(0, 0, c.width, c.height).data;
    let n = 0;
    for (let i = 0; i < d.length; i += 4) {
      const r = d[i], gr = d[i + 1], bl = d[i + 2];
      if (bl > r + 40 && gr > r + 20 && bl > gr && r < 150) n++;  // the car's cyan-blue
    }
    return n;
  });
  assert.ok(body > 500, `${body} pixels of the car's colour`);
  // Another vehicle can be followed from the page's buttons.
  await page.click("text=vehicle 2");
  await page.waitForFunction(() => window.vdyn.followed === 2 && window.vdyn.states > 0, null, { timeout: 10000 });
});
