// GIS files dropped anywhere on the page (or chosen with "Import GIS
// files…"): a drop-zone highlight while dragging, then a dialog that reads
// the files (drop-import-model.ts: the page or the server's import), lists
// their polygons and lines with what each becomes (survey area, no-fly
// zone, corridor line, not used), the features skipped and the files'
// faults. Nothing on the map changes until "Import" is pressed, so a bad
// file never costs what the user had.

import type { LonLat } from './api';
import { byId, h } from './dom';
import { formatArea, formatLength } from './format';
import type { PolygonRings } from './geo-import';
import {
  IMPORT_ACCEPT,
  ROLE_NAMES,
  defaultRoles,
  describePlan,
  importPlan,
  readFiles,
  rolesFault,
  rolesFor,
  setAllRoles,
  type FileResult,
  type ImportPlan,
  type ImportedShape,
  type Role,
  type Shape,
} from './drop-import-model';
import { closeOverlay, openOverlay } from './overlay';

/** What the import reads from and writes to: the survey's areas and corridor. */
export interface DropImportTarget {
  areas(): { roi: PolygonRings | null; nfz: PolygonRings[] };
  corridorLine(): LonLat[] | null;
  /** Puts the shapes on the map and into the survey form (as drawing them would). */
  apply(plan: ImportPlan): void;
}

function isShown(id: string): boolean {
  const el = document.getElementById(id);
  return el !== null && !el.hidden;
}

/** Rows listed one by one; past this many the group choices decide for the rest. */
const MAX_ROWS = 300;

/** Group choices: what all polygons (or all lines) become. */
type GroupChoice = 'default' | Role;

export class DropImport {
  private readonly dialog = byId('import-dialog');
  private readonly zone = byId('drop-zone');
  private results: FileResult[] = [];
  private shapes: ImportedShape[] = [];
  private roles: Role[] = [];
  private busy = false;
  /** Where the focus was before the dialog opened (it goes back there). */
  private returnFocus: HTMLElement | null = null;
  private dragDepth = 0;
  /** Ends the page-wide drag and drop listeners (stop()). */
  private readonly listening = new AbortController();

  constructor(
    private readonly target: DropImportTarget,
    private readonly fetchImpl: typeof fetch = (...args) => fetch(...args),
  ) {
    const chooser = byId<HTMLInputElement>('import-gis');
    chooser.accept = IMPORT_ACCEPT;
    chooser.addEventListener('change', () => {
      const files = Array.from(chooser.files ?? []);
      chooser.value = '';
      if (files.length) void this.handleFiles(files);
    });
    byId('import-apply').addEventListener('click', () => this.apply());
    byId('import-cancel').addEventListener('click', () => this.close());
    this.dialog.addEventListener('keydown', (e) => {
      if (e.key === 'Escape') {
        e.stopPropagation();
        this.close();
      }
    });
    byId<HTMLSelectElement>('import-polygons-as').addEventListener('change', (e) => this.groupChanged('polygon', (e.target as HTMLSelectElement).value as GroupChoice));
    byId<HTMLSelectElement>('import-lines-as').addEventListener('change', (e) => this.groupChanged('line', (e.target as HTMLSelectElement).value as GroupChoice));
    this.listenForDrops(document);
  }

  // ---- dragging and dropping ----

  private listenForDrops(doc: Document): void {
    const carriesFiles = (e: DragEvent) => Array.from(e.dataTransfer?.types ?? []).includes('Files');
    // A drop on a file input (the DEM upload) stays that input's own.
    const onFileInput = (e: DragEvent) => e.target instanceof HTMLInputElement && e.target.type === 'file';
    const options = { signal: this.listening.signal };
    doc.addEventListener('dragenter', (e) => {
      if (!carriesFiles(e) || onFileInput(e)) return;
      e.preventDefault();
      this.dragDepth++;
      this.setHighlight(true);
    }, options);
    doc.addEventListener('dragover', (e) => {
      if (!carriesFiles(e) || onFileInput(e)) return;
      // Without this the browser would open the file in place of the page (and the work on it).
      e.preventDefault();
      if (e.dataTransfer) e.dataTransfer.dropEffect = this.accepting() ? 'copy' : 'none';
      this.setHighlight(true);
    }, options);
    doc.addEventListener('dragleave', (e) => {
      if (!carriesFiles(e) || onFileInput(e)) return;
      this.dragDepth = Math.max(0, this.dragDepth - 1);
      if (this.dragDepth === 0) this.setHighlight(false);
    }, options);
    doc.addEventListener('drop', (e) => {
      if (!carriesFiles(e) || onFileInput(e)) return;
      e.preventDefault();
      this.dragDepth = 0;
      this.setHighlight(false);
      const files = Array.from(e.dataTransfer?.files ?? []);
      if (files.length && this.accepting()) void this.handleFiles(files);
    }, options);
  }

  /** Stops listening for drops on the page (the tests make one import per page). */
  stop(): void {
    this.listening.abort();
  }

  /** Whether a drop is taken now: not while another dialog (signing in) is over the page, nor while files are being read. */
  private accepting(): boolean {
    if (this.busy) return false;
    return ![...document.querySelectorAll<HTMLElement>('.overlay')].some((o) => !o.hidden && o !== this.dialog);
  }

  private setHighlight(on: boolean): void {
    this.zone.hidden = !on;
    document.body.classList.toggle('dragging-files', on);
    byId('drop-zone-text').textContent = this.accepting()
      ? 'Drop to import into the survey: areas, no-fly zones or a corridor line from a zipped Shapefile, KML, KMZ, GPX, GeoPackage or GeoJSON file.'
      : this.busy
        ? 'Still reading the files dropped before: drop these once that is done.'
        : isShown('signin')
          ? 'Sign in first, then drop the files again.'
          : 'Close the dialog first, then drop the files.';
  }

  // ---- reading ----

  /** Reads files and shows what they hold; files dropped while the dialog is open are added to it. */
  async handleFiles(files: File[]): Promise<void> {
    const adding = !this.dialog.hidden;
    if (!adding) {
      this.results = [];
      this.shapes = [];
      this.roles = [];
      this.returnFocus = document.activeElement instanceof HTMLElement ? document.activeElement : null;
      for (const id of ['import-polygons-as', 'import-lines-as']) byId<HTMLSelectElement>(id).value = 'default';
    }
    this.busy = true;
    byId('import-heading').textContent = 'Import GIS files';
    this.setBusyText(`Reading ${files.map((f) => f.name).join(', ')}…`);
    byId<HTMLButtonElement>('import-apply').disabled = true;
    if (!adding) {
      this.render();
      openOverlay(this.dialog, byId('import-cancel'));
    }
    try {
      const read = await readFiles(files, this.fetchImpl);
      const newShapes = read.flatMap((r) => r.shapes);
      const hasRoi = this.target.areas().roi !== null || this.roles.includes('roi');
      let newRoles = defaultRoles(newShapes, hasRoi);
      // One corridor line at most: one already chosen keeps its place.
      if (this.roles.includes('corridor')) newRoles = newRoles.map((r) => (r === 'corridor' ? 'none' : r));
      this.results.push(...read);
      this.shapes.push(...newShapes);
      this.roles.push(...newRoles);
    } finally {
      this.busy = false;
    }
    const n = this.shapes.length;
    this.setBusyText(n ? `${n} shape${n > 1 ? 's' : ''} read. Choose what each becomes, then press Import.` : 'Nothing to import.');
    this.render();
    if (!this.dialog.hidden) (n ? byId('import-apply') : byId('import-cancel')).focus();
  }

  private setBusyText(text: string): void {
    byId('import-busy').textContent = text;
  }

  // ---- the dialog ----

  private groupChanged(type: Shape['type'], choice: GroupChoice): void {
    if (choice === 'default') {
      // The defaults again for this kind of shape, the other kind as chosen.
      const defaults = defaultRoles(this.shapes, this.target.areas().roi !== null);
      this.roles = this.roles.map((r, i) => (this.shapes[i].shape.type === type ? defaults[i] : r));
    } else {
      this.roles = setAllRoles(this.shapes, this.roles, type, choice);
    }
    this.render();
  }

  private render(): void {
    const errors = this.results.map((r) => r.error).filter((e): e is string => e !== null);
    const errorList = byId('import-errors');
    errorList.replaceChildren(...errors.map((e) => h('li', {}, e)));
    errorList.hidden = errors.length === 0;

    const messages = this.results.flatMap((r) => r.messages.map((m) => `${r.file}: ${m}`));
    const skipped = byId<HTMLDetailsElement>('import-skipped');
    skipped.hidden = messages.length === 0;
    byId('import-skipped-count').textContent = `${messages.length} message${messages.length === 1 ? '' : 's'} about features skipped`;
    byId('import-messages').replaceChildren(...messages.map((m) => h('li', {}, m)));
    skipped.open = messages.length > 0 && messages.length <= 10;

    const polygons = this.shapes.filter((s) => s.shape.type === 'polygon').length;
    const lines = this.shapes.length - polygons;
    byId('import-choices').hidden = this.shapes.length === 0;
    byId('import-polygons-row').hidden = polygons === 0;
    byId('import-lines-row').hidden = lines === 0;
    byId('import-polygons-label').textContent = `All ${polygons} polygon${polygons === 1 ? '' : 's'}`;
    byId('import-lines-label').textContent = `All ${lines} line${lines === 1 ? '' : 's'}`;
    byId('import-polygons-default').textContent =
      this.target.areas().roi === null ? 'the largest the survey area, the others no-fly zones' : 'no-fly zones (there is a survey area already)';

    const rows = this.shapes.slice(0, MAX_ROWS).map((s, i) => this.row(s, i));
    byId('import-features').querySelector('tbody')!.replaceChildren(...rows);
    const more = this.shapes.length - rows.length;
    byId('import-more').hidden = more <= 0;
    byId('import-more').textContent = more > 0 ? `${more} more shapes are not listed: the choices for all polygons and all lines above decide for them.` : '';

    this.showVerdict();
  }

  private row(s: ImportedShape, i: number): HTMLTableRowElement {
    const id = `import-role-${i}`;
    const select = h('select', { id, 'aria-label': `${s.label} (${s.file}) becomes` });
    for (const role of rolesFor(s.shape)) select.append(h('option', { value: role }, ROLE_NAMES[role]));
    select.value = this.roles[i];
    select.addEventListener('change', () => {
      this.roles[i] = select.value as Role;
      this.showVerdict();
    });
    const what = s.shape.type === 'polygon' ? `polygon, ${formatArea(s.size)}` : `line, ${formatLength(s.size)}`;
    return h('tr', {}, h('td', {}, s.file), h('td', {}, s.label), h('td', {}, what), h('td', {}, select));
  }

  /** The summary of what Import does, or why it cannot. */
  private showVerdict(): void {
    const apply = byId<HTMLButtonElement>('import-apply');
    const fault = this.shapes.length ? rolesFault(this.shapes, this.roles) : null;
    const error = byId('import-form-error');
    error.textContent = fault ?? '';
    error.hidden = fault === null;
    const plan = importPlan(this.shapes, this.roles);
    byId('import-summary').textContent = this.shapes.length && !fault ? describePlan(plan, this.had()) : '';
    apply.hidden = this.shapes.length === 0;
    apply.disabled = this.busy || fault !== null || this.shapes.length === 0;
    byId('import-cancel').textContent = this.shapes.length === 0 && !this.busy ? 'Close' : 'Cancel';
  }

  private had(): { roi: boolean; corridor: boolean } {
    return { roi: this.target.areas().roi !== null, corridor: this.target.corridorLine() !== null };
  }

  private apply(): void {
    if (this.busy || rolesFault(this.shapes, this.roles) !== null) return;
    const plan = importPlan(this.shapes, this.roles);
    const summary = describePlan(plan, this.had()).replace(/^Imports /, 'Imported ');
    const files = this.results.filter((r) => r.shapes.length).map((r) => r.file);
    const messages = this.results.flatMap((r) => r.messages.map((m) => `${r.file}: ${m}`));
    const errors = this.results.map((r) => r.error).filter((e): e is string => e !== null);
    this.target.apply(plan);
    this.close();
    this.report(`From ${files.join(', ')}: ${summary}`, [...errors, ...messages]);
  }

  /** What the last import did and skipped, kept in the survey panel after the dialog closes. */
  private report(text: string, notes: string[]): void {
    byId('import-status').textContent = text;
    const details = byId<HTMLDetailsElement>('import-report');
    details.hidden = notes.length === 0;
    byId('import-report-count').textContent = `${notes.length} note${notes.length === 1 ? '' : 's'} on what was not imported`;
    byId('import-report-list').replaceChildren(...notes.map((m) => h('li', {}, m)));
  }

  private close(): void {
    if (this.dialog.hidden) return;
    closeOverlay(this.dialog);
    this.returnFocus?.focus();
  }
}
