// Small behaviours on top of server-rendered pages; every page works without this file.
(function () {
  "use strict";

  // A cookie's value, read when asked: the CSRF token changes when one signs in again.
  window.robotideCookie = function (name) {
    var found = document.cookie.split("; ").find(function (c) { return c.startsWith(name + "="); });
    return found ? decodeURIComponent(found.split("=")[1]) : "";
  };

  function followLog() {
    var log = document.getElementById("log");
    var follow = document.getElementById("follow");
    if (log && (!follow || follow.checked)) log.scrollTop = log.scrollHeight;
  }

  // Refresh a camera <img> once it has loaded, only while the page is visible.
  function refreshCamera(img) {
    var every = parseInt(img.dataset.refresh, 10) || 1000;
    var base = img.src.split("?")[0];
    function next() {
      setTimeout(function () {
        if (document.hidden) return next();
        img.src = base + "?t=" + Date.now();
      }, every);
    }
    img.addEventListener("load", next);
    img.addEventListener("error", next);
  }

  document.addEventListener("DOMContentLoaded", function () {
    followLog();
    document.querySelectorAll("img[data-refresh]").forEach(refreshCamera);
  });
  document.addEventListener("htmx:wsAfterMessage", followLog);
})();
