// The project switcher: the project new work goes into (sent as
// `project_id` on every create) and whose work the lists show; a new
// project by name; what the caller's role there allows.

import { ApiError, apiContext } from './api';
import { accounts, canEdit, type Project, type Role, type Session } from './account-api';
import { byId, h } from './dom';
import { ErrorSlots } from './errors-ui';
import { closeOverlay, openOverlay } from './overlay';

/** A project as the switcher names it: whose it is, and the role when it is not "owner". */
export function projectLabel(p: Project): string {
  if (p.personal) return `${p.name} (personal)`;
  return p.role === 'owner' ? p.name : `${p.name} (${p.role})`;
}

/** The project to start with: the one chosen last if still there, else the personal one, else the first. */
export function chooseProject(projects: Project[], last: string | null, personalId: string | null): Project | null {
  return projects.find((p) => p.id === last) ?? projects.find((p) => p.id === personalId) ?? projects[0] ?? null;
}

/** What the caller cannot do in a project, in plain words (empty when an editor or owner). */
export function roleNote(p: Project | null): string {
  if (!p || canEdit(p.role)) return '';
  return `You are a viewer in “${p.name}”: you can open and download its work, but not plan, upload or delete there.`;
}

export class ProjectSwitcher {
  private readonly select = byId<HTMLSelectElement>('project-select');
  private readonly dialog = byId('project-dialog');
  private readonly dialogErrors = new ErrorSlots(this.dialog, 'project', [{ prefix: '/name', field: 'name', label: 'Project name' }]);
  private readonly errors = new ErrorSlots(document.body, 'account', []);
  private projects: Project[] = [];
  private session: Session | null = null;

  constructor(private readonly changed: (project: Project | null) => void) {
    this.select.addEventListener('change', () => this.choose(this.select.value));
    byId('new-project').addEventListener('click', () => {
      this.dialogErrors.clear();
      byId<HTMLInputElement>('project-name').value = '';
      openOverlay(this.dialog);
    });
    byId('project-cancel').addEventListener('click', () => this.closeDialog());
    this.dialog.addEventListener('keydown', (e) => {
      if ((e as KeyboardEvent).key === 'Escape') this.closeDialog();
    });
    byId('project-form').addEventListener('submit', (e) => {
      e.preventDefault();
      void this.create();
    });
  }

  get current(): Project | null {
    return this.projects.find((p) => p.id === apiContext.projectId) ?? null;
  }

  /** The caller's role in a project; null when it is none of theirs (or unknown). */
  roleOf(projectId: string | null | undefined): Role | null {
    return this.projects.find((p) => p.id === projectId)?.role ?? null;
  }

  nameOf(projectId: string | null | undefined): string | null {
    return this.projects.find((p) => p.id === projectId)?.name ?? null;
  }

  /** Loads the signed-in user's projects and chooses the one used last (or the personal one). */
  async load(session: Session): Promise<void> {
    this.session = session;
    byId('account').hidden = false;
    try {
      this.projects = (await accounts.listProjects()).items;
    } catch (err) {
      this.errors.showError(err);
      return;
    }
    const first = chooseProject(this.projects, localStorage.getItem(this.storageKey()), session.personal_project_id);
    this.fill();
    this.choose(first?.id ?? '', false);
  }

  private storageKey(): string {
    return `terraplan.project.${this.session?.user.id ?? ''}`;
  }

  private fill(): void {
    // Names are the users' own words: text, never markup.
    this.select.replaceChildren(...this.projects.map((p) => h('option', { value: p.id }, projectLabel(p))));
  }

  /** Makes a project the current one; `notify`: tell the page (its lists change). */
  choose(id: string, notify = true): void {
    const project = this.projects.find((p) => p.id === id) ?? null;
    apiContext.projectId = project?.id ?? null;
    this.select.value = project?.id ?? '';
    if (project) localStorage.setItem(this.storageKey(), project.id);
    const note = byId('project-role');
    note.textContent = roleNote(project);
    note.hidden = note.textContent === '';
    byId('members-open').hidden = !project;
    if (notify) this.changed(project);
  }

  /** Closes the new-project dialog; focus goes back to `to` (the button that opened it). */
  private closeDialog(to: HTMLElement = byId('new-project')): void {
    closeOverlay(this.dialog);
    to.focus();
  }

  private async create(): Promise<void> {
    this.dialogErrors.clear();
    const name = byId<HTMLInputElement>('project-name').value.trim();
    if (name === '') {
      this.dialogErrors.show('name', 'Project name: give the new project a name.');
      return;
    }
    const button = byId<HTMLButtonElement>('project-create');
    button.disabled = true;
    try {
      const project = await accounts.createProject(name);
      this.projects.push(project);
      this.fill();
      this.closeDialog(this.select);
      this.choose(project.id);
    } catch (err) {
      if (err instanceof ApiError) this.dialogErrors.showError(err);
      else throw err;
    } finally {
      button.disabled = false;
    }
  }
}
