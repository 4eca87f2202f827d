// node render.mjs CHROMIUM PAGE_URL OUT.png
// Opens PAGE_URL (index.html with its query) in headless Chromium (SwiftShader WebGL), waits for
// window.viewerDone, writes the canvas as a PNG and prints {"three": ..., "materials": [...]}.
import { writeFile } from "node:fs/promises";
import puppeteer from "puppeteer-core";

const [chromium, url, out] = process.argv.slice(2);
const browser = await puppeteer.launch({
  executablePath: chromium,
  headless: true,
  args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--disable-gpu-sandbox", "--no-first-run", "--disable-extensions"],
});
try {
  const page = await browser.newPage();
  const logs = [];
  page.on("console", (m) => logs.push(m.text()));
  page.on("pageerror", (e) => logs.push(String(e)));
  await page.goto(url, { waitUntil: "load", timeout: 30000 });
  await page.waitForFunction("window.viewerDone !== undefined", { timeout: 30000 });
  const done = await page.evaluate("window.viewerDone");
  if (done !== "ok") throw new Error(done + "\n" + logs.join("\n"));
  const dataUrl = await page.evaluate(() => document.querySelector("canvas").toDataURL("image/png"));
  await writeFile(out, Buffer.from(dataUrl.split(",")[1], "base64"));
  process.stdout.write(JSON.stringify(await page.evaluate("window.viewerInfo")) + "\n");
} finally {
  await browser.close();
}
