// "Send to vehicle" in the survey results: when the server allows vehicle
// links (GET /api/v1/vehicle-links), each sortie's downloads get a button
// that opens a small form — the vehicle address picked from the allowed list
// (a port typed for a pattern), fence and rally points — and sends the
// sortie's mission over MAVLink through the server, with a progress bar from
// its events and the server's message when it fails. The logic is in
// vehicle-upload-model.ts.
import { ApiError, type Survey } from './api';
import { h } from './dom';
import {
  LINKS_OFF,
  chosenAddress,
  fetchVehicleLinks,
  portLabel,
  portRange,
  refusalText,
  sendToVehicle,
  uploadBody,
  type UploadView,
  type VehicleLinks,
} from './vehicle-upload-model';

export class VehicleUpload {
  private links: Promise<VehicleLinks> | null = null;

  constructor(private readonly fetchFn: typeof fetch = (...a) => fetch(...a)) {}

  /** The server's vehicle links, asked once (they change only with a restart). */
  private allowed(): Promise<VehicleLinks> {
    this.links ??= fetchVehicleLinks(this.fetchFn).then((l) => {
      // Ask again next time when the answer was no answer.
      if (!l.enabled) this.links = null;
      return l;
    });
    return this.links;
  }

  /**
   * Adds a "Send to vehicle" button to each sortie's row of `list` (items
   * with `data-uav` and `data-sortie`) when the server allows vehicle links.
   */
  async attach(list: HTMLElement, survey: Survey): Promise<void> {
    const links = await this.allowed().catch(() => LINKS_OFF);
    if (!links.enabled || !list.isConnected) return;
    list.querySelectorAll<HTMLElement>('li[data-uav][data-sortie]').forEach((li, row) => {
      const uav = survey.uavs.find((u) => u.id === li.dataset.uav);
      const sortie = uav?.sorties.find((s) => String(s.number) === li.dataset.sortie);
      if (!uav || !sortie || li.querySelector('.send-vehicle')) return;
      const several = uav.sorties.length > 1;
      const tag = several ? ` (sortie ${sortie.number})` : '';
      const button = h('button', { type: 'button', class: 'send-vehicle', 'aria-expanded': 'false', 'aria-label': `Send ${uav.id} to vehicle${tag}` }, 'Send to vehicle');
      let form: HTMLFormElement | null = null;
      button.addEventListener('click', () => {
        if (!form) {
          form = this.form(survey.id, uav.id, several ? sortie.number : null, Boolean(sortie.files.rally), links, `vs-${row}`, tag);
          li.append(form);
        } else {
          form.hidden = !form.hidden;
        }
        button.setAttribute('aria-expanded', String(!form.hidden));
      });
      li.append(' ', button);
    });
  }

  /** The form of one sortie; `id` prefixes its controls' ids. */
  private form(surveyId: string, uav: string, sortie: number | null, hasRally: boolean, links: VehicleLinks, id: string, tag: string): HTMLFormElement {
    const select = h('select', { id: `${id}-to` }, ...links.addresses.map((a, k) => h('option', { value: String(k) }, a.address)));
    const port = h('input', { id: `${id}-port`, type: 'number', inputmode: 'numeric', min: '1' });
    const portText = h('span', {}, 'Port');
    const portRow = h('label', { for: `${id}-port` }, portText, ' ', port);
    const fence = h('input', { id: `${id}-fence`, type: 'checkbox' });
    fence.checked = true;
    const rally = h('input', { id: `${id}-rally`, type: 'checkbox' });
    rally.checked = hasRally;
    const rallyRow = h('label', { for: `${id}-rally` }, rally, ' Rally points');
    rallyRow.hidden = !hasRally;
    const send = h('button', { type: 'submit' }, 'Send');
    const stop = h('button', { type: 'button' }, 'Stop');
    stop.hidden = true;
    const progress = h('progress', { max: '1', value: '0', 'aria-label': `Upload progress of ${uav}${tag}` });
    progress.hidden = true;
    const status = h('p', { class: 'upload-status', role: 'status' });
    const error = h('p', { class: 'error', role: 'alert' });
    error.hidden = true;
    const form = h(
      'form',
      { class: 'vehicle-send', 'aria-label': `Send ${uav} to a vehicle${tag}`, novalidate: '' },
      h('label', { for: `${id}-to` }, 'Vehicle ', select),
      ' ',
      portRow,
      ' ',
      h('label', { for: `${id}-fence` }, fence, ' Fence'),
      ' ',
      rallyRow,
      ' ',
      send,
      ' ',
      stop,
      progress,
      status,
      error,
    );
    const entry = () => links.addresses[Number(select.value)] ?? links.addresses[0];
    const showPort = () => {
      const e = entry();
      const range = e ? portRange(e) : null;
      portRow.hidden = !range;
      portText.textContent = e ? portLabel(e) : 'Port';
      if (range) {
        port.min = String(range.lo);
        port.max = String(range.hi);
        port.placeholder = range.lo === range.hi ? String(range.lo) : `${range.lo}–${range.hi}`;
      }
    };
    select.addEventListener('change', showPort);
    showPort();
    const showError = (text: string | null) => {
      error.textContent = text ?? '';
      error.hidden = text === null;
    };
    let running: AbortController | null = null;
    stop.addEventListener('click', () => running?.abort());
    form.addEventListener('submit', (e) => {
      e.preventDefault();
      if (running) return;
      // A new try: the last one's outcome goes.
      showError(null);
      status.textContent = '';
      progress.hidden = true;
      progress.value = 0;
      const e0 = entry();
      if (!e0) return;
      const chosen = chosenAddress(e0, port.value);
      if ('fault' in chosen) {
        showError(chosen.fault);
        port.focus();
        return;
      }
      const show = (view: UploadView) => {
        progress.hidden = false;
        progress.value = view.fraction;
        status.textContent = view.status;
        if (view.error) showError(view.error);
      };
      running = new AbortController();
      send.disabled = true;
      stop.hidden = false;
      status.textContent = 'Connecting…';
      sendToVehicle(surveyId, uav, uploadBody(chosen.address, sortie, fence.checked, hasRally && rally.checked), show, running.signal, this.fetchFn)
        .catch((err: unknown) => {
          progress.hidden = true;
          status.textContent = '';
          showError(err instanceof ApiError ? refusalText(err.problem) : String(err));
        })
        .finally(() => {
          running = null;
          send.disabled = false;
          stop.hidden = true;
        });
    });
    return form;
  }
}
