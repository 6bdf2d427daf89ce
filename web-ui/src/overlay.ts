// Dialogs over the page (sign-in, new project, members): while one is open
// the page under it is inert, so focus and clicks stay in the dialog.

const OVERLAYS = '.overlay';
const PAGE = ['.skip', '.topbar', '.layout'];

/** Shows a dialog and focuses `focus` (else its first field). */
export function openOverlay(overlay: HTMLElement, focus?: HTMLElement | null): void {
  overlay.hidden = false;
  setPageInert(true);
  (focus ?? overlay.querySelector<HTMLElement>('input, select, button'))?.focus();
}

/** Hides a dialog; the page comes back once no other dialog is open. */
export function closeOverlay(overlay: HTMLElement): void {
  overlay.hidden = true;
  const stillOpen = [...document.querySelectorAll<HTMLElement>(OVERLAYS)].some((o) => !o.hidden);
  if (!stillOpen) setPageInert(false);
}

function setPageInert(inert: boolean): void {
  for (const selector of PAGE) {
    for (const el of document.querySelectorAll<HTMLElement>(selector)) {
      if (inert) el.setAttribute('inert', '');
      else el.removeAttribute('inert');
    }
  }
}
