// Saved work: the surveys, costmaps, routes and DEMs stored on the server,
// newest first, each with Open and Delete (Delete only where the caller's
// role allows it). With accounts: of the chosen project, or of all the
// caller's projects, each then naming its project.

import { api, apiContext } from './api';
import { canEdit, type Role } from './account-api';
import { byId, h } from './dom';
import { ErrorSlots } from './errors-ui';
import { formatArea, formatDate, formatDuration, formatLength } from './format';

export interface SavedActions {
  openSurvey(id: string): Promise<void>;
  openCostmap(id: string): Promise<void>;
  openRoute(id: string): Promise<void>;
  openDem(id: string): Promise<void>;
  /** Something was deleted: lists elsewhere on the page may be stale. */
  deleted(kind: Kind, id: string): void;
}

type Kind = 'survey' | 'costmap' | 'route' | 'dem';

export interface Entry {
  id: string;
  title: string;
  detail: string;
  projectId?: string | null;
}

/** The caller's projects, on a server with accounts. */
export interface ProjectLookup {
  roleOf(projectId: string | null | undefined): Role | null;
  nameOf(projectId: string | null | undefined): string | null;
}

/**
 * One saved item: its title and detail as text (names are the users' own
 * words, never markup), Open, and Delete when `deletable`.
 */
export function savedItem(e: Entry, deletable: boolean, open: () => void, remove: (button: HTMLButtonElement) => void): HTMLLIElement {
  const openButton = h('button', { type: 'button', 'aria-label': `Open ${e.title}` }, 'Open');
  openButton.addEventListener('click', open);
  const buttons = h('div', { class: 'buttons' }, openButton);
  if (deletable) {
    const del = h('button', { type: 'button', class: 'danger', 'aria-label': `Delete ${e.title}` }, 'Delete');
    del.addEventListener('click', () => remove(del));
    buttons.append(del);
  } else {
    buttons.append(h('span', { class: 'hint' }, 'view only'));
  }
  return h('li', {}, h('div', {}, h('strong', {}, e.title), h('br'), h('small', {}, e.detail)), buttons);
}

export class SavedPanel {
  private readonly errors = new ErrorSlots(byId('saved-panel'), 'saved', []);
  private readonly allProjects = byId<HTMLInputElement>('saved-all-projects');
  /** Set once signed in on a server with accounts. */
  private projects: ProjectLookup | null = null;

  constructor(private readonly actions: SavedActions) {
    byId('saved-refresh').addEventListener('click', () => void this.refresh());
    this.allProjects.addEventListener('change', () => void this.refresh());
  }

  /** Accounts: lists follow the chosen project (or all of them) and Delete follows the role. */
  useProjects(projects: ProjectLookup): void {
    this.projects = projects;
    byId('saved-all-field').hidden = false;
  }

  async refresh(): Promise<void> {
    this.errors.clear();
    const status = byId('saved-status');
    status.textContent = 'Loading…';
    try {
      const all = this.projects !== null && this.allProjects.checked;
      const [surveys, costmaps, routes, dems] = await Promise.all([api.listSurveys(all), api.listCostmaps(all), api.listRoutes(all), api.listDems(all)]);
      this.fill('saved-surveys', 'survey', surveys.items.map((s) => ({
        id: s.id,
        projectId: s.project_id,
        title: s.name ?? `Unnamed survey ${idTail(s.id)}`,
        detail: `${formatDate(s.created_at)} · ${formatArea(s.area_m2)} · ${s.uav_count} UAV${s.uav_count === 1 ? '' : 's'} · ${formatDuration(s.makespan_s)}`,
      })));
      this.fill('saved-costmaps', 'costmap', costmaps.items.map((c) => ({
        id: c.id,
        projectId: c.project_id,
        title: c.name ?? `${c.vehicle.name} costmap ${idTail(c.id)}`,
        detail: `${formatDate(c.created_at)} · ${c.vehicle.name} · ${c.status}`,
      })));
      this.fill('saved-routes', 'route', routes.items.map((r) => ({
        id: r.id,
        projectId: r.project_id,
        title: r.name ?? `Unnamed route ${idTail(r.id)}`,
        detail: `${formatDate(r.created_at)} · ${formatLength(r.length_2d_m)}${r.parent_id ? ' · replanned' : ''}`,
      })));
      this.fill('saved-dems', 'dem', dems.items.map((d) => ({
        id: d.id,
        projectId: d.project_id,
        title: d.name ?? d.file_name ?? `DEM ${idTail(d.id)}`,
        detail: `${formatDate(d.created_at)} · ${d.width}×${d.height} · ${d.crs.name}`,
      })));
      status.textContent = '';
    } catch (err) {
      status.textContent = '';
      this.errors.showError(err);
    }
  }

  private fill(listId: string, kind: Kind, entries: Entry[]): void {
    const list = byId(listId);
    if (entries.length === 0) {
      list.replaceChildren(h('li', { class: 'empty' }, 'None yet.'));
      return;
    }
    const named = this.projects !== null && this.allProjects.checked;
    list.replaceChildren(
      ...entries.map((e) => {
        const projectName = named ? this.projects!.nameOf(e.projectId) : null;
        const shown = projectName ? { ...e, detail: `${e.detail} · project ${projectName}` } : e;
        return savedItem(shown, this.deletable(e), () => void this.open(kind, e.id), (del) => void this.remove(kind, e, del));
      }),
    );
  }

  /** Without accounts everything may be deleted; with them, by editors and owners of its project. */
  private deletable(e: Entry): boolean {
    return this.projects === null || canEdit(this.projects.roleOf(e.projectId ?? apiContext.projectId));
  }

  private async open(kind: Kind, id: string): Promise<void> {
    this.errors.clear();
    try {
      if (kind === 'survey') await this.actions.openSurvey(id);
      else if (kind === 'costmap') await this.actions.openCostmap(id);
      else if (kind === 'route') await this.actions.openRoute(id);
      else await this.actions.openDem(id);
    } catch (err) {
      this.errors.showError(err);
    }
  }

  private async remove(kind: Kind, e: Entry, button: HTMLButtonElement): Promise<void> {
    // A second click while the first is being answered would delete twice (and report the second as not found).
    if (button.disabled) return;
    const extra =
      kind === 'costmap'
        ? ' Its routes are deleted with it.'
        : kind === 'dem'
          ? ' The costmaps, routes and surveys made from it are kept, without its hillshade; new routes on those costmaps have no heights.'
          : '';
    if (!window.confirm(`Delete “${e.title}”?${extra}`)) return;
    this.errors.clear();
    button.disabled = true;
    try {
      if (kind === 'survey') await api.deleteSurvey(e.id);
      else if (kind === 'costmap') await api.deleteCostmap(e.id);
      else if (kind === 'route') await api.deleteRoute(e.id);
      else await api.deleteDem(e.id);
      this.actions.deleted(kind, e.id);
      await this.refresh();
    } catch (err) {
      this.errors.showError(err);
    } finally {
      button.disabled = false;
    }
  }
}

/**
 * A short tag telling unnamed items apart: the end of the id. (Ids are
 * UUIDv7: their start is the creation time, the same for items made
 * together; the end is random.)
 */
export function idTail(id: string): string {
  return `#${id.replace(/-/g, '').slice(-6)}`;
}
