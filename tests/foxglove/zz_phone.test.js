"use strict";
const { test, after } = require("node:test");
const path = require("path");
const { chromium } = require("playwright-core");
const h = require("./harness");
let browser;
after(async () => { if (browser) await browser.close(); await h.stopGracefully(); });
test("phone", async () => {
  h.server(["--vehicle-ids", "1,2"]);
  h.demoDrive();
  const b = await h.bridge("bridge");
  browser = await chromium.launch({ executablePath: "/usr/bin/chromium", args: ["--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--disable-background-networking"] });
  const ctx = await browser.newContext({ viewport: { width: 390, height: 844 }, deviceScaleFactor: 2, isMobile: true, hasTouch: true });
  const page = await ctx.newPage();
  await page.goto(`http://127.0.0.1:${b.port}/`);
  await page.waitForFunction(() => window.vdyn.states > 3000 && window.vdyn.speedKmh > 30, null, { timeout: 60000 });
  await page.screenshot({ path: "/tmp/phone/phone.png" });
});
