// Anda até a parede, vira para longe dela e diz o rumo.
const { Robot } = require('robot');

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

async function main() {
  const bot = new Robot();

  await bot.drive(0.3, 0);
  while ((await bot.sensors()).range >= 0.5) { // metros
    await sleep(20);
  }
  await bot.stop();

  await bot.drive(0, 1.0); // gira a 1 rad/s
  await sleep(1500);
  await bot.stop();

  const rumo = Number((await bot.sensors()).heading.toFixed(1));
  console.log(`rumo: ${rumo.toFixed(1)}`);
  await bot.show('rumo', rumo);
}

main(); // um erro rejeita a Promise de main: o Node o imprime e sai com status 1
