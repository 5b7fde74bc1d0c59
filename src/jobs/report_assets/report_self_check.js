// Counts broken images and drawn plots once the page has loaded: nothing a person sees; the
// headless-browser test reads the data attributes on <body>.
window.addEventListener('load', function () {
  var imgs = document.querySelectorAll('img'), broken = 0;
  imgs.forEach(function (i) { if (!i.complete || i.naturalWidth === 0) broken++; });
  var frames = document.querySelectorAll('iframe.plot'), drawn = 0;
  frames.forEach(function (f) { var d = f.contentDocument; if (d && d.querySelector('svg path')) drawn++; });
  document.body.setAttribute('data-images', imgs.length);
  document.body.setAttribute('data-broken-images', broken);
  document.body.setAttribute('data-plots', drawn);
});
