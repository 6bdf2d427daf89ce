// Shows field messages next to their controls. Each panel's error slots are
// elements with id `${scope}-${field}-error` placed right after the control
// they concern; `${scope}-form-error` takes everything else.

import { ApiError } from './api';
import { problemToMessages, type FieldRule } from './problems';

export class ErrorSlots {
  constructor(
    private readonly root: HTMLElement,
    private readonly scope: string,
    private readonly rules: FieldRule[],
    /** The field taking messages no control is named for. */
    private readonly fallback = 'form',
  ) {}

  clear(): void {
    for (const el of this.root.querySelectorAll<HTMLElement>(`[id^="${this.scope}-"][id$="-error"]`)) {
      el.textContent = '';
      el.hidden = true;
    }
    for (const el of this.root.querySelectorAll('[aria-invalid="true"]')) el.removeAttribute('aria-invalid');
  }

  /** Shows one message in a field's slot (appending to what is there); `controlId` names the control at fault when the slot serves several. */
  show(field: string, text: string, controlId?: string): void {
    const slot = this.slot(field) ?? this.slot(this.fallback);
    if (!slot) return;
    slot.textContent = slot.textContent ? `${slot.textContent} ${text}` : text;
    slot.hidden = false;
    // Mark the control at fault, so screen readers announce it.
    const control = (controlId ? document.getElementById(controlId) : null) ?? this.root.querySelector<HTMLElement>(`[aria-describedby~="${slot.id}"]`);
    control?.setAttribute('aria-invalid', 'true');
  }

  /** Shows any error: an API problem split per field, or a plain message. */
  showError(err: unknown): void {
    if (err instanceof ApiError) {
      const messages = problemToMessages(err.problem, this.rules, this.fallback);
      for (const m of messages) this.show(m.field, m.text, m.control);
      // Bring the first message into view for keyboard and screen users.
      this.slot(messages[0]?.field ?? this.fallback)?.scrollIntoView({ block: 'center' });
    } else {
      this.show(this.fallback, err instanceof Error ? err.message : String(err));
    }
  }

  private slot(field: string): HTMLElement | null {
    return this.root.querySelector<HTMLElement>(`#${this.scope}-${field}-error`);
  }
}
