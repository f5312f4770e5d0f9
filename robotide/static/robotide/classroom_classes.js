// The classroom's class pages (templates/classroom/class_*.html): the sheet's Print button.
"use strict";

document.addEventListener("DOMContentLoaded", () => {
  const print = document.getElementById("sheet-print");
  if (print) print.addEventListener("click", () => window.print());
});
