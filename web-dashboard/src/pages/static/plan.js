// The exercise forms: a chosen plan file is read into the plan text box (the form still
// posts text; nothing is uploaded separately).
"use strict";
document.querySelectorAll("input[type=file][data-into]").forEach(function (input) {
  input.addEventListener("change", function () {
    var file = input.files && input.files[0];
    var box = document.getElementById(input.dataset.into);
    if (!file || !box) {
      return;
    }
    if (file.size > 64 * 1024) {
      box.value = "";
      window.alert("A plan has at most 64 KiB.");
      return;
    }
    file.text().then(function (text) {
      box.value = text;
      var details = box.closest("details");
      if (details) {
        details.open = true;
      }
    });
  });
});
