// Drive to the wall, turn away from it, and tell the heading.
const { Robot } = require('robot');

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

async function main() {
  const bot = new Robot();

  await bot.drive(0.3, 0);
  while ((await bot.sensors()).range >= 0.5) { // metres
    await sleep(20);
  }
  await bot.stop();

  await bot.drive(0, 1.0); // turn at 1 rad/s
  await sleep(1500);
  await bot.stop();

  const heading = Number((await bot.sensors()).heading.toFixed(1));
  console.log(`heading: ${heading.toFixed(1)}`);
  await bot.show('heading', heading);
}

main(); // an error rejects main's Promise: Node prints it and exits with status 1
